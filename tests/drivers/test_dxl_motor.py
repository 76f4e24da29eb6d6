"""The emulated servo motor's grid is the per-point recursion of its filters, to the last bit.

The motor runs its two tracking lags and its ripple noise in SciPy's compiled DF2T kernel where
it loads, else in its own loop, which stops running the lags once a still shaft reaches the
recursion's fixed point; it skips the ripple and noise terms where the shaft is at rest. Both
paths are tested. The reference here computes every grid point the plain way:
:func:`gyrocal.drivers.emulated.iir.lfilter` (itself checked against SciPy) for the three
recursions, the ripple and the noise term added on every point.
"""

import numpy as np
import pytest

import gyrocal.drivers.emulated.dxl.motor as motor_module
from gyrocal.drivers.emulated.dxl.motor import (
    ServoMotor,
    _tracking_lags,
    plan_hold,
    plan_position,
    plan_velocity,
)
from gyrocal.drivers.emulated.iir import lfilter


class _PointByPoint(ServoMotor):
    """The motor with every grid point computed by the plain recursions."""

    def _compute(self, m: int) -> None:
        g = self._grid
        k_first = g.k0 + g.n
        t = self.t_start + (k_first + np.arange(m)) * self.dt
        pt, vt = self.plan.evaluate(t)
        al = self._alpha
        last = g.n - 1
        y1, _ = lfilter([1.0 - al], [1.0, -al], pt, zi=[al * g.y1[last]])
        y2, _ = lfilter([1.0 - al], [1.0, -al], y1, zi=[al * g.y2[last]])
        speed = np.abs(vt)
        env = np.minimum(speed / self.params.envelope_speed, 1.0)
        p = y2 + env * (np.sin(np.multiply.outer(pt, self._orders) + self._phases) @ self._amps)
        u1 = g.u[last]
        u2 = g.u[last - 1] if last >= 1 else 0.0
        xi = self._noise(k_first, m) * self._g
        u, _ = lfilter([1.0], [1.0, -self._c1, -self._c2], xi,
                       zi=[self._c1 * u1 + self._c2 * u2, self._c2 * u1])
        self._append(p + speed * u, y1, y2, u)


@pytest.fixture(params=["compiled", "loop"])
def recursions(request, monkeypatch):
    """The motor's recursions in the compiled kernel (where it loads), or in its own loop."""
    if request.param == "loop":
        monkeypatch.setattr(motor_module, "compiled", lambda: False)
    else:
        assert motor_module.compiled()  # the installed SciPy has it: the fast path is tested
    return request.param


def _moves(t0, p0, v0):
    return plan_position(t0, p0, v0, 2.0, 3.0, 20.0)


COMMANDS = [  # (time, plan): moves, holds long enough to reach the fixed point, a move cut
    (0.3, _moves),  # short by another command, a velocity ramp and a stop
    (2.5, lambda t0, p0, v0: plan_position(t0, p0, v0, -1.0, 2.0, 10.0)),
    (3.1, lambda t0, p0, v0: plan_position(t0, p0, v0, 0.5, 3.0, 20.0)),
    (6.0, lambda t0, p0, v0: plan_velocity(t0, p0, v0, 4.0, 15.0)),
    (7.2, lambda t0, p0, v0: plan_hold(t0, p0)),
]


@pytest.mark.parametrize("seed", [11, 12])
def test_the_motor_grid_equals_the_point_by_point_recursion_through_moves_and_holds(
        seed, recursions):
    fast, plain = ServoMotor(0.0, seed=seed), _PointByPoint(0.0, seed=seed)
    reads = np.arange(0.0, 9.0, 0.0037)  # reads between the commands, as a poll loop makes
    for m in (fast, plain):
        cmds = list(COMMANDS)
        for t in reads:
            while cmds and cmds[0][0] <= t:
                m.command(*cmds.pop(0))
            m.sample(float(t))
    a, b = fast._grid, plain._grid
    assert (a.k0, a.n) == (b.k0, b.n)
    assert a.n > 17000
    for name in ("p", "y1", "y2", "u"):
        assert getattr(a, name)[:a.n].tobytes() == getattr(b, name)[:b.n].tobytes(), name


def test_the_lags_fixed_point_shortcut_gives_the_recursions_numbers(recursions):
    rng = np.random.default_rng(3)
    al = ServoMotor(0.0)._alpha
    for x in (np.full(900, 1.7), np.r_[np.linspace(0.0, 1.0, 300), np.full(700, 1.0)],
              np.r_[np.full(400, -0.2), rng.normal(size=5).cumsum()], np.array([0.4])):
        y1_last, y2_last = rng.normal(size=2)
        r1, _ = lfilter([1.0 - al], [1.0, -al], x, zi=[al * y1_last])
        r2, _ = lfilter([1.0 - al], [1.0, -al], r1, zi=[al * y2_last])
        y1, y2 = _tracking_lags(al, x, float(y1_last), float(y2_last))
        assert y1.tobytes() == r1.tobytes()
        assert y2.tobytes() == r2.tobytes()
