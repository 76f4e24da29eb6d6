"""kit.gravity with a calibration that stores the home pose its "up" refers to: a recording that
starts off the home pose gets the right specific force (checked against scipy's rotations)."""

import math
from types import SimpleNamespace

import numpy as np
from scipy.spatial.transform import Rotation

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.gravity import force_of

#: Servos 1 (base, about x), 2 (y) and 3 (z, next to the sensor: the vertical one at home).
AXES = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def _cal(home: bool) -> GyroCalibration:
    kin = {"chain": [1, 2, 3], "axes": AXES, "reference_angles_rad": [0.0, 0.0, 0.0]}
    if home:
        kin |= {"home_angles_rad": [0.0, 0.0, 0.0], "up_servo": [3, 1]}
    eye = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    return GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0), matrix=eye,
                           kinematics=kin, g_sensitivity={"matrix": [[1e-3] * 3] * 3,
                                                          "matrix_std": None,
                                                          "directions": [list(r) for r in eye]})


def _recording(start: list[float]) -> SimpleNamespace:
    t = np.array([0.0, 10.0])
    angles = {m: np.full(2, a) for m, a in zip((1, 2, 3), start, strict=True)}
    return SimpleNamespace(
        manifest={"gimbal": {"motors": [{"id": 1, "axis": "x"}, {"id": 2, "axis": "y"},
                                        {"id": 3, "axis": "z"}]}},
        encoder=lambda m: (t, angles[m]))


def test_a_recording_that_starts_off_home_gets_up_from_the_stored_home_pose():
    start = [0.4, 0.0, 0.3]  # the base tilted 0.4 rad off home, the sensor's servo turned 0.3
    rec = _recording(start)
    # at home "up" is +z (servo 3's axis); the pose turns the sensor by Rot(x, 0.4) then
    # Rot(z, 0.3) (base first), so the sensor sees "up" turned back by the inverse
    R = Rotation.from_rotvec([0.4, 0.0, 0.0]) * Rotation.from_rotvec([0.0, 0.0, 0.3])
    truth = R.inv().apply([0.0, 0.0, 1.0])
    src, why = force_of(rec, _cal(home=True))
    assert why is None
    np.testing.assert_allclose(src.at(np.array([1.0, 5.0])), [truth, truth], atol=1e-12)
    # without the stored pose the replay takes the recording's first pose for home, where servo
    # 3 is not vertical: "up" would be +z, 0.4 rad off
    src, why = force_of(rec, _cal(home=False))
    assert why is None
    np.testing.assert_allclose(src.at(np.array([1.0])), [[0.0, 0.0, 1.0]], atol=1e-12)
    assert math.degrees(math.acos(truth[2])) > 20
