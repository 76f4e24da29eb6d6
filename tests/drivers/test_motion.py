import numpy as np
import pytest

from gyrocal.drivers.emulated.motion import ConstantRate, FunctionMotion, MotionSource


def test_constant_rate_repeats_its_vector():
    m = ConstantRate((0.1, -0.2, 1.5))
    w = m.rate(np.array([0.0, 0.5, 1.0]))
    assert w.shape == (3, 3)
    np.testing.assert_array_equal(w, [[0.1, -0.2, 1.5]] * 3)
    assert isinstance(m, MotionSource)


def test_function_motion_checks_shape_and_values():
    spin = FunctionMotion(lambda t: np.column_stack([np.sin(t), 0 * t, 0 * t]))
    np.testing.assert_allclose(spin.rate(np.array([np.pi / 2]))[0], [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="shape"):
        FunctionMotion(lambda t: t).rate(np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="non-finite"):
        FunctionMotion(lambda t: np.full((t.size, 3), np.nan)).rate(np.array([0.0]))
    with pytest.raises(ValueError, match="omega"):
        ConstantRate((1.0, 2.0))
