"""The emulators' IIR filters against ``scipy.signal.lfilter`` (the oracle they replace): the
same numbers to the last bit, for the forms the emulators use (the servos' tracking lags and
ripple noise, the chips' bilinear low-pass, the coloured noise's Gauss–Markov steps)."""

import numpy as np
import pytest
from scipy.signal import lfilter as scipy_lfilter

from gyrocal.drivers.emulated.iir import lfilter


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_emulators_filters_are_scipys_to_the_last_bit(seed):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((400, 3)) * 10.0 ** rng.uniform(-4, 4, 3)
    al = float(rng.uniform(0.5, 0.999))
    k = float(rng.uniform(0.05, 3.0))
    b, a = k / (1 + k), (k - 1) / (k + 1)
    c1, c2 = float(rng.uniform(1.5, 1.99)), float(-rng.uniform(0.5, 0.99))
    cases = [([1.0 - al], [1.0, -al], x[:, 0], [al * 0.37]),  # servo tracking lag
             ([b, b], [1.0, a], x, rng.standard_normal((1, 3))),  # bilinear low-pass, 3 axes
             ([1.0], [1.0, -c1, -c2], x[:, 1], [0.1, -0.2]),  # ripple noise, second order
             ([1.0], [1.0, -al], x, rng.standard_normal((1, 3)))]  # Gauss-Markov steps
    for bb, aa, xx, zi in cases:
        want, want_z = scipy_lfilter(bb, aa, xx, axis=0, zi=zi)
        got, got_z = lfilter(bb, aa, xx, zi=zi)
        assert np.array_equal(got, want) and np.array_equal(got_z, want_z)
    impulse = np.r_[1.0, np.zeros(300)]
    assert np.array_equal(lfilter([1.0], [1.0, -c1, -c2], impulse)[0],
                          scipy_lfilter([1.0], [1.0, -c1, -c2], impulse))


def test_the_compiled_kernel_and_the_python_loop_agree_to_the_last_bit(monkeypatch):
    """Either path of :func:`lfilter` may run (the compiled one where SciPy's extension loads):
    both give the same numbers for every form and shape the emulators pass, from a given
    state or from rest, on strided input."""
    import gyrocal.drivers.emulated.iir as iir

    assert iir._kernel() is not None  # the installed SciPy has it: the fast path is tested
    rng = np.random.default_rng(7)
    for trial in range(60):
        order, n, m = 1 + trial % 2, int(rng.integers(1, 200)), int(rng.integers(1, 7))
        x = (rng.standard_normal((n, 2 * m)) * 10.0 ** rng.uniform(-4, 4, 2 * m))[:, ::2]
        a = [1.0 + (trial % 5 == 0), *rng.uniform(-0.9, 0.9, order)]
        b = list(rng.uniform(-1, 1, 1 + trial % (order + 1)))
        zi = rng.standard_normal((order, m)) if trial % 4 else None
        for xx, z in ((x, zi), (x[:, 0], None if zi is None else zi[:, 0])):
            fast = lfilter(b, a, xx, zi=z)
            monkeypatch.setattr(iir, "_KERNEL", False)
            slow = lfilter(b, a, xx, zi=z)
            monkeypatch.setattr(iir, "_KERNEL", None)
            for f, s in zip(fast, slow, strict=True):
                assert f.shape == s.shape and np.array_equal(f, s)


def test_a_kernel_that_refuses_its_arguments_falls_back_to_the_python_loop(monkeypatch):
    """The kernel is SciPy's private API: a version that takes other arguments must cost speed,
    not a traceback, and give the Python loop's numbers."""
    import gyrocal.drivers.emulated.iir as iir

    x = np.random.default_rng(3).standard_normal((40, 3))
    monkeypatch.setattr(iir, "_KERNEL", False)
    want = lfilter([0.2, 0.1], [1.0, -0.5], x)

    def refuses(*args):
        raise TypeError("_linear_filter() takes other arguments")

    monkeypatch.setattr(iir, "_KERNEL", refuses)
    got = lfilter([0.2, 0.1], [1.0, -0.5], x)
    assert all(np.array_equal(g, w) for g, w in zip(got, want, strict=True))
    assert iir._KERNEL is False  # and it is not tried again


def test_a_calibrations_emulators_do_not_import_scipy_signal():
    import subprocess
    import sys

    code = ("import sys, gyrocal.kit.sim, gyrocal.kit.protocol, gyrocal.kit.pipeline; "
            "print('scipy.signal' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"
