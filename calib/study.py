"""The paper's simulation study (Section III), reproducible and extended to our estimator.

Presets:

``normal``
    k ~ U(0.8, 1.2), b ~ U(-0.1, 0.1) rad/s, mount misalignment up to 10 % (0.1 rad), white noise
    σ = 0.035 and 0.2 rad/s per sample at 200 Hz, 5 % speed ripple, 1 rad/s, one revolution each
    way with 3 s waits (the paper's protocol), 30 sensors × 500 repetitions = 15,000 runs per
    noise level.
``extreme``
    The same with k ~ U(1.2, 2.0) and |b| ~ U(0.1, 0.2) rad/s.
``speed-sweep``
    Mean squared error of each parameter (paper Eq. 10) against speed, 0.3 to 3.0 rad/s in steps
    of 0.1 (fewer runs per speed by default).
``convergence``
    The paper's Table I cases: Algorithm 1's iterates.
``demo``
    Before/after: a sine-wave rotation of 1 rad/s amplitude at 0.75 Hz with equal projection on
    the three axes, RMS error per axis of the raw and the calibrated readings.

Every run is simulated at sample level (:func:`gyrocal.calib.simulate.simulate_runs`) and fitted by
all
three estimators on the same data. Work is split into chunks with independent seeds from one
:class:`numpy.random.SeedSequence`, so results do not depend on how chunks are scheduled; pass a
parallel ``map`` (e.g. a process pool's) to :func:`run_study` to use several cores.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import (
    estimate,
    fit_iterative_ls,
    iterative_ls_batch,
    lm_solve,
    paired_axis_batch,
)
from gyrocal.calib.observations import pool_noise
from gyrocal.calib.simulate import (
    EXTREME,
    NORMAL,
    SensorPreset,
    SimProtocol,
    draw_mount_axes,
    draw_sensors,
    simulate_runs,
)

__all__ = [
    "METHOD_ORDER",
    "PRESETS",
    "ErrorStats",
    "StudyConfig",
    "StudyResult",
    "convergence_table",
    "demo_before_after",
    "error_stats",
    "run_study",
    "speed_sweep",
]

METHOD_ORDER = ("iterative-ls", "levenberg-marquardt", "paired-axis")
PARAMS = ("k_x", "k_y", "k_z", "b_x", "b_y", "b_z")


@dataclass(frozen=True)
class StudyConfig:
    """One Monte Carlo study.

    Attributes
    ----------
    name : str
    sensors : SensorPreset
    n_sensors, reps : int
        Sensors drawn, and runs per sensor (each with a new mount and new noise).
    noise_levels : tuple of float
        White noise per sample, rad/s.
    protocol : SimProtocol
    misalignment : float
        Largest mount rotation, rad.
    seed : int
    """

    name: str = "normal"
    sensors: SensorPreset = NORMAL
    n_sensors: int = 30
    reps: int = 500
    noise_levels: tuple[float, ...] = (0.035, 0.2)
    protocol: SimProtocol = field(default_factory=lambda: SimProtocol(
        speed=1.0, turns=1, odr_hz=200.0, rest_s=3.0, ripple=0.05))
    misalignment: float = 0.1
    seed: int = 2023

    @property
    def runs(self) -> int:
        """Runs per noise level."""
        return self.n_sensors * self.reps


PRESETS: dict[str, StudyConfig] = {
    "normal": StudyConfig(),
    "extreme": StudyConfig(name="extreme", sensors=EXTREME),
}


def _chunk(args: tuple[Any, ...]) -> dict[str, np.ndarray]:
    """Simulate and fit one chunk of runs (module-level so a process pool can pickle it)."""
    seed_seq, scale, bias, protocol, noise, misalignment, lm = args
    rng = np.random.default_rng(seed_seq)
    B = scale.shape[0]
    axes = draw_mount_axes(rng, B, misalignment)
    runs = simulate_runs(rng, scale, bias, axes, protocol, noise)
    truth = np.concatenate([scale, bias], axis=1)
    out: dict[str, np.ndarray] = {}
    k, b, it, ok = iterative_ls_batch(runs.mean, runs.rate)
    out["iterative-ls"] = np.concatenate([k, b], axis=1) - truth
    out["iterative-ls:iterations"] = it
    out["iterative-ls:ok"] = ok
    n = runs.count.size
    noise_all = np.concatenate([runs.noise, runs.rest_noise], axis=1)
    pooled, _ = pool_noise(noise_all, np.concatenate([runs.count, runs.rest_count]))
    ratio = pooled / noise_all
    pa = paired_axis_batch(runs.mean, runs.rate, runs.motor_index, runs.mean_std * ratio[:, :n],
                           runs.rate_std, runs.rest_mean, runs.rest_mean_std * ratio[:, n:])
    out["paired-axis"] = np.concatenate([pa.scale, pa.bias], axis=1) - truth
    out["paired-axis:iterations"] = pa.iterations
    out["paired-axis:ok"] = pa.converged
    out["paired-axis:std"] = np.sqrt(np.einsum("bii->bi", pa.covariance)[:, :6])
    if lm:
        err = np.full((B, 6), np.nan)
        its = np.zeros(B, dtype=np.int64)
        oks = np.zeros(B, dtype=bool)
        for i in range(B):
            r = lm_solve(runs.mean[i], runs.rate[i])
            ok = r.status > 0
            if ok:
                x = r.x.copy()
                x[:3] = np.abs(x[:3])  # the residuals depend on k² only
                err[i] = x - truth[i]
            its[i], oks[i] = r.nfev, ok
        out["levenberg-marquardt"] = err
        out["levenberg-marquardt:iterations"] = its
        out["levenberg-marquardt:ok"] = oks
    return out


@dataclass(frozen=True)
class ErrorStats:
    """Box-plot statistics of one parameter's estimation error."""

    median: float
    q1: float
    q3: float
    whisker_lo: float
    whisker_hi: float
    rms: float
    mean: float

    @classmethod
    def of(cls, e: np.ndarray) -> ErrorStats:
        """Statistics of the finite values of ``e`` (whiskers: 1.5 IQR, Tukey)."""
        e = e[np.isfinite(e)]
        q1, med, q3 = np.percentile(e, [25, 50, 75])
        iqr = q3 - q1
        lo = float(e[e >= q1 - 1.5 * iqr].min())
        hi = float(e[e <= q3 + 1.5 * iqr].max())
        return cls(float(med), float(q1), float(q3), lo, hi, float(np.sqrt(np.mean(e**2))),
                   float(np.mean(e)))


def error_stats(err: np.ndarray) -> dict[str, ErrorStats]:
    """Per-parameter :class:`ErrorStats` of an ``(N, 6)`` error array."""
    return {p: ErrorStats.of(err[:, j]) for j, p in enumerate(PARAMS)}


@dataclass(frozen=True, eq=False)
class StudyResult:
    """Errors of every run and estimator, per noise level.

    ``errors[noise][method]`` is an ``(N, 6)`` array of estimate − truth in the order
    ``k_x, k_y, k_z, b_x, b_y, b_z``; ``extra[noise]`` holds iteration counts, success flags and
    the paired-axis standard deviations.
    """

    config: StudyConfig
    errors: dict[float, dict[str, np.ndarray]]
    extra: dict[float, dict[str, np.ndarray]]

    def stats(self) -> dict[float, dict[str, dict[str, ErrorStats]]]:
        """Per noise level, per method, per parameter."""
        return {
            noise: {m: error_stats(e) for m, e in by.items()}
            for noise, by in self.errors.items()
        }

    def coverage(self, noise: float, level: float = 0.95) -> np.ndarray:
        """Fraction of runs whose paired-axis ``level`` interval holds the truth, per parameter."""
        from scipy.special import ndtri

        z = ndtri(0.5 + level / 2)
        e = self.errors[noise]["paired-axis"]
        s = self.extra[noise]["paired-axis:std"]
        return np.mean(np.abs(e) <= z * s, axis=0)


def run_study(
    config: StudyConfig,
    *,
    map_fn: Callable[[Callable[[Any], Any], Iterable[Any]], Iterable[Any]] = map,
    chunk_runs: int = 250,
    lm: bool = True,
) -> StudyResult:
    """Run a Monte Carlo study: every run fitted by every estimator on the same data.

    Parameters
    ----------
    config : StudyConfig
    map_fn : callable
        ``map``-like; a process pool's ``map`` spreads the chunks over cores.
    chunk_runs : int
        Runs per chunk.
    lm : bool
        Include ``scipy.optimize.least_squares(method="lm")`` (one call per run, the slowest).

    Returns
    -------
    StudyResult
    """
    if config.n_sensors < 1 or config.reps < 1:
        raise CalibInputError("n_sensors and reps must be positive")
    if chunk_runs < 1:
        raise CalibInputError("chunk_runs must be positive")
    root = np.random.SeedSequence(config.seed)
    sensor_seq, run_seq = root.spawn(2)
    scale_s, bias_s = draw_sensors(np.random.default_rng(sensor_seq), config.n_sensors,
                                   config.sensors)
    sensor_of_run = np.repeat(np.arange(config.n_sensors), config.reps)
    errors: dict[float, dict[str, np.ndarray]] = {}
    extra: dict[float, dict[str, np.ndarray]] = {}
    level_seqs = run_seq.spawn(len(config.noise_levels))
    for noise, lseq in zip(config.noise_levels, level_seqs, strict=True):
        n_chunks = -(-config.runs // chunk_runs)
        seqs = lseq.spawn(n_chunks)
        jobs = []
        for c in range(n_chunks):
            sel = sensor_of_run[c * chunk_runs : (c + 1) * chunk_runs]
            jobs.append((seqs[c], scale_s[sel], bias_s[sel], config.protocol, noise,
                         config.misalignment, lm))
        parts = list(map_fn(_chunk, jobs))
        merged = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
        errors[noise] = {m: merged[m] for m in METHOD_ORDER if m in merged}
        extra[noise] = {k: v for k, v in merged.items() if ":" in k}
    return StudyResult(config=config, errors=errors, extra=extra)


def speed_sweep(
    speeds: np.ndarray,
    *,
    base: StudyConfig | None = None,
    map_fn: Callable[[Callable[[Any], Any], Iterable[Any]], Iterable[Any]] = map,
    lm: bool = False,
) -> dict[float, dict[float, dict[str, np.ndarray]]]:
    """Mean squared error of each parameter (paper Eq. 10) at each speed.

    Returns
    -------
    dict
        ``{noise: {speed: {method: mse (6,)}}}``.
    """
    base = base or StudyConfig(name="speed-sweep", n_sensors=30, reps=20)
    out: dict[float, dict[float, dict[str, np.ndarray]]] = {n: {} for n in base.noise_levels}
    for speed in speeds:
        p = base.protocol
        cfg = StudyConfig(
            name=base.name, sensors=base.sensors, n_sensors=base.n_sensors, reps=base.reps,
            noise_levels=base.noise_levels,
            protocol=SimProtocol(speed=float(speed), turns=p.turns, odr_hz=p.odr_hz,
                                 rest_s=p.rest_s, ripple=p.ripple, window=p.window),
            misalignment=base.misalignment, seed=base.seed + int(round(speed * 1000)),
        )
        res = run_study(cfg, map_fn=map_fn, lm=lm)
        for noise, by in res.errors.items():
            out[noise][float(speed)] = {m: np.nanmean(e**2, axis=0) for m, e in by.items()}
    return out


#: The paper's Table I: actual values of three simulated gyroscopes (k, b).
TABLE_I = (
    ("high scale factor error", (1.9074, 1.9529, 1.5635), (0.0827, 0.0265, -0.0805)),
    ("high bias", (1.0979, 1.1052, 0.9851), (-0.1046, 0.1995, 0.1565)),
    ("high scale factor error and bias", (1.5044, 1.6494, 1.5282), (0.1483, -0.1282, 0.1794)),
)


def convergence_table(
    *, noise: float = 0.035, speed: float = 1.0, seed: int = 1
) -> list[dict[str, Any]]:
    """Algorithm 1's iterates for the paper's Table I cases (one simulated run each).

    Returns
    -------
    list of dict
        Per case: ``name``, ``actual`` (6,), ``iterates`` (n, 6), ``iterations``, ``converged``.
    """
    rng = np.random.default_rng(seed)
    rows = []
    for name, k, b in TABLE_I:
        scale, bias = np.array([k]), np.array([b])
        runs = simulate_runs(rng, scale, bias, draw_mount_axes(rng, 1),
                             SimProtocol(speed=speed, turns=1, rest_s=3.0), noise)
        r = fit_iterative_ls(runs.observation_set(0), covariance=False)
        rows.append({
            "name": name,
            "actual": np.concatenate([scale[0], bias[0]]),
            "iterates": r.extra.get("history", np.zeros((0, 6))),
            "iterations": r.iterations,
            "converged": r.success,
        })
    return rows


def demo_before_after(
    *, seed: int = 3, noise: float = 0.035, duration_s: float = 20.0, odr_hz: float = 200.0
) -> dict[str, Any]:
    """The paper's before/after demonstration, with every estimator.

    A sensor is drawn from the normal conditions and calibrated on the paper's protocol; then a
    sine-wave rotation (1 rad/s amplitude, 0.75 Hz, 5 % rotation noise) about ``(1, 1, 1)/√3``
    is measured, and the RMS error per axis of the raw and of each calibrated reading against the
    true rate is reported.

    Returns
    -------
    dict
        ``truth`` (k, b), ``estimates`` per method, ``rms_before`` (3,), ``rms_after`` per method.
    """
    rng = np.random.default_rng(seed)
    k, b = draw_sensors(rng, 1)
    runs = simulate_runs(rng, k, b, draw_mount_axes(rng, 1),
                         SimProtocol(speed=1.0, turns=1, rest_s=3.0), noise)
    obs = runs.observation_set(0)
    fits = {m: estimate(obs, m) for m in METHOD_ORDER}
    t = np.arange(0, duration_s, 1 / odr_hz)
    amp = np.sin(2 * np.pi * 0.75 * t) * (1 + 0.05 * rng.standard_normal(t.size))
    u = np.ones(3) / np.sqrt(3)
    g = amp[:, None] * u
    m = g / k[0] - b[0] + noise * rng.standard_normal(g.shape)
    rms = lambda e: np.sqrt(np.mean(e**2, axis=0))  # noqa: E731
    return {
        "truth": np.concatenate([k[0], b[0]]),
        "estimates": {n: np.concatenate([f.scale, f.bias]) for n, f in fits.items()},
        "rms_before": rms(m - g),
        "rms_after": {n: rms(f.scale * (m + f.bias) - g) for n, f in fits.items()},
        "noise_floor": noise * k[0],
    }
