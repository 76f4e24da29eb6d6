"""Exports of a calibration with a temperature model (issue 13).

The C header is compiled with the C compiler and its ``<prefix>_apply_at`` compared with
``GyroCalibration.apply(m, temperature_c=T)`` and with the model's equation written out here.
"""

import subprocess

import numpy as np
import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.thermal import fit_thermal
from gyrocal.kit.cli import main
from tests.kit.c_program import compile_program, needs_gcc
from tests.kit.flight_stacks import (
    ardupilot_gyro,
    ardupilot_invensense,
    px4_gyro,
    px4_invensense,
)

A0 = np.array([[1.0132, 0.0, 0.0], [0.0187, 0.9871, 0.0], [-0.0164, 0.0119, 1.0043]])
A1 = np.array([[3e-4, 0.0, 0.0], [1e-5, -2e-4, 0.0], [0.0, 0.0, 1e-4]])
C = np.array([[0.01, 2e-3, 3e-5], [-0.02, -1.5e-3, 0.0], [0.005, 8e-4, -2e-5]])  # at 25 °C


def make_cal(full=True):
    """A thermal calibration fitted to exact points of the model above (tiny stated σ)."""
    T = np.linspace(20.0, 30.0, 9)
    d = T[:, None] - 25.0
    bias = C[:, 0] + C[:, 1] * d + C[:, 2] * d**2
    gain = A0 + A1 * d[:, :, None]
    if not full:
        gain = np.einsum("nii->ni", gain)
    model = fit_thermal(T, bias, np.full((9, 3), 1e-6), gain, np.full(gain.shape, 1e-6),
                        reference_c=25.0)
    st = model.at(25.0)
    kw = dict(matrix=st.gain, scale=tuple(np.diag(st.gain))) if full else dict(
        scale=tuple(np.diag(st.gain)))
    return GyroCalibration(bias=tuple(st.bias), temperature_c=25.0, temperature_model=model,
                           sensor={"model": "mpu9250"}, **kw)


def expected(m, T, full=True):
    t = min(max(T, 20.0), 30.0)
    d = t - 25.0
    b = C[:, 0] + C[:, 1] * d + C[:, 2] * d**2
    a = A0 + A1 * d
    if not full:
        a = np.diag(np.diag(a))
    return a @ (np.asarray(m) + b)


C_MAIN = r"""
#include <stdio.h>
#include <stdlib.h>
#include "cal.h"
int main(int argc, char **argv)
{
    float m[3], g[3];
    int i;
    (void)argc;
    for (i = 0; i < 3; ++i) m[i] = strtof(argv[i + 1], NULL);
    gyrocal_apply_at(m, strtof(argv[4], NULL), g);
    for (i = 0; i < 3; ++i) printf("%.9e\n", (double)g[i]);
    return 0;
}
"""


@needs_gcc
@pytest.mark.parametrize("full", [True, False])
def test_c_header_applies_the_model_at_the_die_temperature(full, capsys, tmp_path):
    cal = make_cal(full)
    (tmp_path / "cal.json").write_text(cal.to_json())
    assert main(["export", str(tmp_path / "cal.json"), "--format", "c-header"]) == 0
    compile_program(tmp_path, capsys.readouterr().out, C_MAIN)
    m = [0.8, -1.1, 0.4]
    for T in (18.0, 20.0, 23.3, 25.0, 29.9, 40.0):  # outside the range: clamped, both sides
        run = subprocess.run([str(tmp_path / "apply"), *map(repr, m), repr(T)],
                             capture_output=True, text=True, check=True)
        got = np.array([float(x) for x in run.stdout.split()])
        m32 = [float(np.float32(x)) for x in m]
        np.testing.assert_allclose(got, expected(m32, T, full), atol=2e-6)
        with pytest.warns() if not 20.0 <= T <= 30.0 else _no_warning():
            py = cal.apply(np.array(m32), temperature_c=T)
        np.testing.assert_allclose(got, py, atol=2e-6)


class _no_warning:
    def __enter__(self):
        import warnings

        self._cm = warnings.catch_warnings()
        self._cm.__enter__()
        warnings.simplefilter("error")

    def __exit__(self, *exc):
        return self._cm.__exit__(*exc)


def export_text(capsys, tmp_path, cal, fmt, *options):
    (tmp_path / "cal.json").write_text(cal.to_json())
    code = main(["export", str(tmp_path / "cal.json"), "--format", fmt, *options])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out, err


def gyrocal_bias_corrected(raw, T):
    """What gyrocal's model adds before the gain: raw + b(clamp(T)) (the model above)."""
    t = min(max(T, 20.0), 30.0)
    d = t - 25.0
    return np.asarray(raw) + C[:, 0] + C[:, 1] * d + C[:, 2] * d**2


@pytest.mark.parametrize("full", [True, False])
def test_px4_thermal_parameters_remove_the_same_bias(full, capsys, tmp_path):
    out, err = export_text(capsys, tmp_path, make_cal(full), "px4-thermal", "--imu-index", "1")
    rows = [line.split("\t") for line in out.splitlines() if not line.startswith("#")]
    assert all(r[:2] == ["1", "1"] and len(r) == 5 for r in rows)
    params = {r[2]: float(r[3]) for r in rows}
    assert params["TC_G_ENABLE"] == 1 and params["TC_G1_ID"] == 0
    assert {r[4] for r in rows if r[2].startswith("TC_G1_X")} == {"9"}  # REAL32
    assert (params["TC_G1_TMIN"], params["TC_G1_TMAX"], params["TC_G1_TREF"]) == (20, 30, 25)
    raw = np.array([0.3, -0.2, 0.1])
    for T in (15.0, 20.0, 22.5, 27.0, 30.0, 45.0):
        # PX4's MPU-9250 driver publishes (x, -y, -z): the parameters are in that frame
        np.testing.assert_allclose(px4_gyro(params, "mpu9250", raw, T, n=1),
                                   px4_invensense(gyrocal_bias_corrected(raw, T)), atol=1e-7)
    assert "set it to the gyro's device ID" in err and "scale" in err
    out, err = export_text(capsys, tmp_path, make_cal(full), "px4-thermal", "--device-id", "7")
    assert "1\t1\tTC_G0_ID\t7\t6" in out and "device ID" not in err


def test_ardupilot_thermal_parameters_remove_the_same_bias(capsys, tmp_path):
    out, err = export_text(capsys, tmp_path, make_cal(), "ardupilot-thermal")
    params = dict(line.split(",") for line in out.splitlines() if not line.startswith("#"))
    params = {k: float(v) for k, v in params.items()}
    assert params["INS_TCAL1_ENABLE"] == 1 and params["INS_GYR1_CALTEMP"] == 25.0
    raw = np.array([0.3, -0.2, 0.1])
    for T in (12.0, 20.0, 24.0, 29.5, 30.0, 50.0):
        # ArduPilot's Invensense backend builds (y, x, -z): the parameters are in that frame
        np.testing.assert_allclose(ardupilot_gyro(params, "mpu9250", raw, T),
                                   ardupilot_invensense(gyrocal_bias_corrected(raw, T)),
                                   atol=1e-7)
    out, _ = export_text(capsys, tmp_path, make_cal(), "ardupilot-thermal", "--imu-index", "2")
    assert "INS_TCAL2_GYR1_X," in out and "INS_GYR2OFFS_X," in out


def test_flight_stack_exports_need_a_temperature_model(capsys, tmp_path):
    cal = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0))
    (tmp_path / "cal.json").write_text(cal.to_json())
    for fmt, extra in (("px4-thermal", []), ("ardupilot-thermal", ["--imu-index", "0"])):
        code = main(["export", str(tmp_path / "cal.json"), "--format", fmt, *extra])
        assert code == 2 and "temperature_model" in capsys.readouterr().err
    (tmp_path / "t.json").write_text(make_cal().to_json())
    code = main(["export", str(tmp_path / "t.json"), "--format", "ardupilot-thermal",
                 "--imu-index", "0"])
    assert code == 2 and "outside 1..3" in capsys.readouterr().err


def test_px4_thermal_id_comes_from_the_calibrations_chip_bus_and_address(capsys, tmp_path):
    """Without --device-id, TC_G0_ID is PX4's device ID of the recorded chip, bus and address
    (worked out by hand: I2C 1 | bus 1 << 3 | 0x68 << 8 | DRV_IMU_DEVTYPE_MPU9250 0x24 << 16);
    --device-id still wins."""
    from dataclasses import replace

    cal = replace(make_cal(), sensor={"model": "mpu9250", "i2c_bus": 1, "i2c_address": 0x68})
    out, err = export_text(capsys, tmp_path, cal, "px4-thermal")
    assert "1\t1\tTC_G0_ID\t2385929\t6" in out
    assert "TC_G0_ID from the calibration: device ID 2385929" in err
    out, err = export_text(capsys, tmp_path, cal, "px4-thermal", "--device-id", "7")
    assert "1\t1\tTC_G0_ID\t7\t6" in out and "device ID 2385929" not in err


@pytest.mark.parametrize("bad", ["-5", "0", str(1 << 24), "abc"])
def test_a_device_id_outside_px4s_24_bits_is_refused(bad, capsys, tmp_path):
    """--device-id must fit PX4's DeviceId (24 bits, not 0): anything else is exit 2 naming the
    value, before a .params file with an ID PX4 can never match is written."""
    (tmp_path / "t.json").write_text(make_cal().to_json())
    code = main(["export", str(tmp_path / "t.json"), "--format", "px4-thermal",
                 f"--device-id={bad}"])
    out, err = capsys.readouterr()
    assert code == 2 and bad in err and "CAL_GYROn_ID" in err and "TC_G0" not in out


def test_px4_thermal_says_why_it_could_not_make_the_id(capsys, tmp_path):
    """A chip PX4 has no devtype for leaves TC_G0_ID 0, and the note says why as well as what
    to do."""
    from dataclasses import replace

    cal = replace(make_cal(), sensor={"model": "lsm6dsox", "i2c_bus": 1, "i2c_address": 0x6A})
    out, err = export_text(capsys, tmp_path, cal, "px4-thermal")
    assert "1\t1\tTC_G0_ID\t0\t6" in out
    assert "TC_G0_ID is 0 (PX4 has no device type for the sensor model 'lsm6dsox'" in err
    out, err = export_text(capsys, tmp_path, cal, "px4-thermal", "--device-id", "0x246809")
    assert "1\t1\tTC_G0_ID\t2385929\t6" in out
