"""Exports of a calibration with a temperature model (issue 13).

The C header is compiled with the C compiler and its ``<prefix>_apply_at`` compared with
``GyroCalibration.apply(m, temperature_c=T)`` and with the model's equation written out here.
"""

import shutil
import subprocess

import numpy as np
import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.thermal import fit_thermal
from gyrocal.kit.cli import main

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


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed: cannot compile "
                    "the exported C header (install gcc to run this test)")
@pytest.mark.parametrize("full", [True, False])
def test_c_header_applies_the_model_at_the_die_temperature(full, capsys, tmp_path):
    cal = make_cal(full)
    (tmp_path / "cal.json").write_text(cal.to_json())
    assert main(["export", str(tmp_path / "cal.json"), "--format", "c-header"]) == 0
    (tmp_path / "cal.h").write_text(capsys.readouterr().out)
    (tmp_path / "main.c").write_text(C_MAIN)
    flags = ["-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-Wdouble-promotion",
             "-Wconversion", "-Wshadow"]
    cc = subprocess.run(["gcc", *flags, "-o", "apply", "main.c"], capture_output=True,
                        text=True, cwd=tmp_path)
    assert cc.returncode == 0, cc.stderr
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
