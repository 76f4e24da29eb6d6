"""Plausibility bounds from the chip's datasheet (issue 28): the sensitivity tolerance and the
zero-rate offset, with room for the paper's extreme sensors (scale up to 2.0, bias ±0.2 rad/s),
and a specific refusal of a power-of-two scale (a full-scale setting mix-up).

The datasheet figures are written out here independently of drivers/imu/chips.py:
- MPU-9250 PS-MPU-9250A-01 §3.1 Table 1: sensitivity tolerance ±3 %, ZRO ±5 °/s.
- LSM9DS1 DocID025715 Rev 3 Table 3: ZRO (G_TyOff) ±30 °/s; no sensitivity tolerance there (the
  MPU-9250's ±3 % stands in).
- ICM-42688-P DS-000347 Table 1: ±0.5 %, ZRO ±0.5 °/s.
- ICM-20948 DS-000189 Table 1: ±1.5 %, ZRO ±5 °/s.
- LSM6DSO DS12140 Table 2: ±1 %, ZRO ±1 °/s.
"""

import math

import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.errors import EstimationError
from gyrocal.kit.pipeline import check_plausible, plausible_bounds

DATASHEET = {  # model: (sensitivity tolerance, zero-rate offset °/s)
    "mpu9250": (0.03, 5.0),
    "lsm9ds1": (0.03, 30.0),
    "icm42688p": (0.005, 0.5),
    "icm20948": (0.015, 5.0),
    "lsm6dsox": (0.01, 1.0),
}


def _check(model, scale, bias, **kw):
    cal = GyroCalibration(scale=scale, bias=bias)
    return check_plausible(cal, {"model": model, "full_scale_dps": 500.0}, **kw)


@pytest.mark.parametrize("model", sorted(DATASHEET))
def test_the_bounds_are_the_datasheets_with_room_for_the_papers_extremes(model):
    tol, zro_dps = DATASHEET[model]
    lo, hi, bias, source = plausible_bounds(model)
    assert hi == pytest.approx(2.0 * (1 + tol) * 1.05) and lo == pytest.approx(1 / hi)
    assert bias == pytest.approx(2.0 * max(math.radians(zro_dps), 0.2))
    assert f"zero-rate offset ±{zro_dps:g} °/s" in source


@pytest.mark.parametrize("model", sorted(DATASHEET))
def test_the_papers_extreme_sensor_is_admitted(model):
    """Fails on the code before issue 28: the bound was 0.5..2 and refused 2.002."""
    assert _check(model, (2.002, 1.3, 1.6), (0.2, -0.2, 0.15)) == []


@pytest.mark.parametrize("factor", [2.0, 4.0, 0.5, 0.25])
def test_a_power_of_two_scale_on_every_axis_is_named_a_full_scale_mixup(factor):
    with pytest.raises(EstimationError, match="power of two") as info:
        _check("mpu9250", (factor * 1.01, factor * 0.99, factor * 1.02), (0.0, 0.0, 0.0))
    assert "imu.range_dps" in str(info.value)


def test_a_bias_beyond_the_chips_offset_says_what_to_check():
    problems = _check("icm42688p", (1.0, 1.0, 1.0), (0.5, 0.0, 0.0), allow=True)
    assert len(problems) == 1 and "beyond ±0.4 rad/s" in problems[0]
    assert "zero-rate offset ±0.5 °/s" in problems[0] and "imu.model" in problems[0]
    # the LSM9DS1's datasheet allows ±30 °/s = 0.52 rad/s: 0.5 rad/s is a sensor, not a mistake
    assert _check("lsm9ds1", (1.0, 1.0, 1.0), (0.5, 0.0, 0.0)) == []


def test_a_sensor_without_a_datasheet_keeps_the_general_bounds():
    assert plausible_bounds("bmi088")[:3] == (0.5, 2.0, None)
    assert _check("bmi088", (1.0, 1.0, 1.0), (1.0, 0.0, 0.0)) == []
    with pytest.raises(EstimationError, match="outside 0.5..2"):
        _check("bmi088", (2.1, 1.0, 1.0), (0.0, 0.0, 0.0))


def test_the_diagonal_note_gives_each_chips_own_cross_axis_figure():
    """The size the diagonal model may miss is the chip's datasheet cross-axis figure
    (ICM-42688-P DS-000347 §3.1 Table 1: ±1.25 %), not the MPU-9250's for every chip."""
    from gyrocal.kit.pipeline import diagonal_note

    assert "±1.25 % of the rate" in diagonal_note("icm42688p", "no poses")
    assert "±2 % of the rate" in diagonal_note("mpu9250", "no poses")
    assert "±2 % of the rate" in diagonal_note("unknown-chip", "no poses")
