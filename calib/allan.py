"""Noise characterisation of a still gyro by the overlapping Allan deviation.

The rate record of each axis is treated as frequency data: the overlapping Allan variance at
averaging time ``τ = m/odr`` is (IEEE Std 952-1997 Annex C; IEEE Std 1554-2005; NIST SP 1065
eq. 11)

    σ²(τ) = 1 / (2 τ² (n − 2m)) · Σ_k (x_{k+2m} − 2 x_{k+m} + x_k)²,

with ``x`` the integrated rate (angle), computed here with numpy in one pass per axis. Its
confidence intervals use Greenhall's equivalent degrees of freedom for the unmodified,
overlapping Allan variance (C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances
based on finite differences", 35th PTTI, 2003; the algorithm NIST SP 1065 §5.3 refers to):
:func:`edf_greenhall`. Both are checked against the ``allantools`` package in the test suite;
the kit does not depend on it (it would pull matplotlib, sphinx and pytest into a plain install).

Three IEEE Std 952 noise terms are read off the curve:

==================  =================  ======================  ==========================
term                coefficient        Allan deviation         unit
==================  =================  ======================  ==========================
angle random walk   ``N``              ``N/√τ`` (slope −½)     rad/s/√Hz
bias instability    ``B``              ``0.664 B`` (floor)     rad/s
rate random walk    ``K``              ``K √(τ/3)`` (slope ½)  rad/s/√s (= rad/s²/√Hz)
==================  =================  ======================  ==========================

How (per axis):

1. The three-term model ``σ²(τ) = N²/τ + (0.664 B)² + K² τ/3`` is fitted to the curve by
   non-negative weighted least squares, the weights the inverse variances ``edf/(2σ⁴)`` of the
   Allan variance estimates (Greenhall edf of the noise type that dominates at each τ).
2. ``N`` is read on the white-noise slope (where ``N²/τ`` is at least half the model): at the
   point nearest τ = 1 s when the curve has one there (IEEE Std 952's reading), else where it
   is best determined; its 95 % interval is widened to hold ``N`` read at every point of that
   slope, so a curve's short-τ structure is in the interval (:func:`_read_white`). ``K`` is
   read at the one averaging time where it is best determined. Each is read as
   ``N² = (σ̂²(τ) − the other fitted terms)·τ``, and likewise ``K²``; the standard deviation
   is that of the one Allan variance estimate they come from,
   ``σ²·√(2/edf)``, carried through. Reading at one τ keeps the uncertainty honest: the
   estimates at different τ of one record are correlated, which a joint fit's covariance would
   ignore.
3. ``B`` is read the same way, from the flicker floor ``(0.664 B)²`` at the τ where it is best
   determined (``0.664 = √(2 ln 2/π)``, IEEE Std 952). The IEEE habit of quoting the curve's
   minimum over 0.664 is biased low (the minimum of noisy points) and high (white noise and
   random walk add to the floor); the minimum is kept in ``adev_min`` for comparison with
   datasheets. Where the curve has no flicker floor, ``B`` is near zero and ``hi95`` bounds it.

Results are frozen dataclasses; :class:`NoiseCharacterisation` round-trips through the
``gyrocal-noise`` v1 JSON document.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import nnls
from scipy.special import chdtri

from gyrocal.calib.errors import CalibInputError, CalibrationFormatError
from gyrocal.calib.noise_sim import FLICKER_FLOOR
from gyrocal.calib.validation import scalar

__all__ = [
    "FORMAT",
    "VERSION",
    "AllanCurve",
    "NoiseCharacterisation",
    "NoiseFigure",
    "PhaseRecord",
    "allan_deviation",
    "characterise_noise",
    "edf_greenhall",
    "min_still_samples",
    "overlapping_avar",
    "overlapping_avar_blocks",
    "phase_blocks",
]

FORMAT = "gyrocal-noise"
VERSION = 1
METHOD = (
    "overlapping Allan deviation (IEEE Std 952-1997 Annex C, IEEE Std 1554-2005, "
    "NIST SP 1065 eq. 11; Greenhall-Riley edf); N, B and K each read at the one tau where best "
    "determined"
)

#: Greenhall's alpha (fractional-frequency power law) of each term: white FM, flicker FM, RW FM.
_ALPHA = (0, -1, -2)
_ONE_SIGMA = math.erf(1.0 / math.sqrt(2.0))
_MIN_SAMPLES = 64


def _as_rate(rate: Any, name: str = "rate") -> np.ndarray:
    try:
        a = np.asarray(rate, dtype=float)
    except (TypeError, ValueError):
        raise CalibInputError(f"{name} must be an (n, 3) array of rad/s") from None
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[1] < 1:
        raise CalibInputError(f"{name} must have shape (n,) or (n, axes), got {a.shape}")
    if a.shape[0] < _MIN_SAMPLES:
        raise CalibInputError(
            f"{name} has {a.shape[0]} samples; an Allan deviation needs at least {_MIN_SAMPLES} "
            "(a still record of many minutes gives useful figures)"
        )
    if not np.all(np.isfinite(a)):
        raise CalibInputError(f"{name} contains NaN or inf; give a clean, gap-free still record")
    return a


@dataclass(frozen=True, eq=False)
class AllanCurve:
    """Overlapping Allan deviation of each axis.

    Attributes
    ----------
    tau_s : ndarray (M,)
        Averaging times, s.
    m : ndarray (M,) of int
        Averaging factors (``tau_s·odr_hz``).
    adev : ndarray (M, A)
        Overlapping Allan deviation per axis, rad/s.
    odr_hz : float
        Sample rate of the record.
    n_samples : int
        Samples per axis.
    edf : ndarray (M, 3)
        Greenhall's equivalent degrees of freedom at each τ for white, flicker and
        random-walk rate noise (columns in that order).
    """

    tau_s: np.ndarray
    m: np.ndarray
    adev: np.ndarray
    odr_hz: float
    n_samples: int
    edf: np.ndarray

    def interval(self, edf: np.ndarray, ci: float = _ONE_SIGMA) -> tuple[np.ndarray, np.ndarray]:
        """Chi-square confidence interval of ``adev`` for given ``edf`` (NIST SP 1065 eq. 45).

        Parameters
        ----------
        edf : ndarray, broadcastable to ``adev``
        ci : float
            Confidence level (default one sigma, 0.683).

        Returns
        -------
        (lo, hi) : ndarrays shaped like ``adev``
        """
        edf = np.broadcast_to(np.asarray(edf, dtype=float), self.adev.shape)
        lo_q, hi_q = (1.0 - ci) / 2.0, (1.0 + ci) / 2.0
        lo = self.adev * np.sqrt(edf / chdtri(edf, 1.0 - hi_q))
        hi = self.adev * np.sqrt(edf / chdtri(edf, 1.0 - lo_q))
        return lo, hi


def _taus_m(n: int, per_octave: int = 2) -> np.ndarray:
    """Averaging factors ~ evenly spaced in log, ``m ≤ n/4`` (Stable32's stop ratio for oadev)."""
    top = math.log2(max(n // 4, 1))
    ms = np.unique(np.round(2.0 ** np.arange(0, top + 1e-9, 1.0 / per_octave)).astype(np.int64))
    return ms[ms >= 1]


# Greenhall & Riley (2003), Table 2: (a0, a1) of the large-r approximation
# 1/edf ≈ (a0 − a1/r)/r for unmodified variances, by alpha, at d = 2 (Allan variance).
_GR_TABLE2_D2 = {0: (2.0 / 3.0, 1.0 / 3.0), -1: (0.852, 0.375), -2: (1.079, 0.368)}
_GR_JMAX = 100


def _gr_sw(t: np.ndarray, alpha: int) -> np.ndarray:
    """Greenhall & Riley eq. 7: the generalised autocovariance ``sw(t)`` of power law ``alpha``.

    ``−|t|``, ``t² ln|t|``, ``|t|³``, ``t⁴ ln|t|``, ``|t|⁵`` for alpha = 2, 1, 0, −1, −2
    (the logarithmic forms are 0 at t = 0).
    """
    at = np.abs(np.asarray(t, dtype=float))
    if alpha % 2 == 0:
        return -at if alpha == 2 else at ** (3 - alpha)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = at ** (3 - alpha) * np.log(at)
    return np.where(at == 0.0, 0.0, out)


def _gr_sx(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """Greenhall & Riley eq. 8: ``sx(t) = F² [2 sw(t) − sw(t − 1/F) − sw(t + 1/F)]``."""
    if math.isinf(f):
        return _gr_sw(t, alpha + 2)
    h = 1.0 / f
    return f * f * (2.0 * _gr_sw(t, alpha) - _gr_sw(t - h, alpha) - _gr_sw(t + h, alpha))


def _gr_sz(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """Greenhall & Riley eq. 9 at d = 2: the second difference of ``sx``, binomial (1 −4 6 −4 1)."""
    return (
        6.0 * _gr_sx(t, f, alpha)
        - 4.0 * (_gr_sx(t - 1.0, f, alpha) + _gr_sx(t + 1.0, f, alpha))
        + _gr_sx(t - 2.0, f, alpha)
        + _gr_sx(t + 2.0, f, alpha)
    )


def _gr_basic_sum(j: int, big_m: float, s: float, f: float, alpha: int) -> float:
    """Greenhall & Riley eq. 10: ``sz(0)² + (1 − J/M) sz(J/S)² + 2 Σ_{j<J} (1 − j/M) sz(j/S)²``."""
    k = np.arange(1, j, dtype=float)
    inner = 2.0 * np.sum((1.0 - k / big_m) * _gr_sz(k / s, f, alpha) ** 2)
    first = float(_gr_sz(np.array(0.0), f, alpha)) ** 2
    second = (1.0 - j / big_m) * float(_gr_sz(np.array(j / s), f, alpha)) ** 2
    return first + second + float(inner)


def edf_greenhall(alpha: int, m: int, n_phase: int) -> float:
    """Equivalent degrees of freedom of the overlapping Allan variance (Greenhall & Riley 2003).

    The unmodified, fully overlapping estimator (``d = 2``, filter factor ``F = m``, stride
    factor ``S = m``), the paper's case 2 for ``alpha ≤ 0``: the exact sum of eq. 10 where it
    has at most ``J_max = 100`` terms, otherwise the Table 2 approximation
    ``1/edf = (a0 − a1/r)/r`` (``r = M/S > 3``) or the truncated sum.

    Parameters
    ----------
    alpha : {0, -1, -2}
        Power-law exponent of the fractional-frequency (rate) noise: 0 white rate noise (angle
        random walk), −1 flicker (bias instability), −2 random-walk rate (rate random walk).
    m : int
        Averaging factor, ``τ = m/odr``.
    n_phase : int
        Number of phase (angle) points, one more than the number of rate samples.

    Returns
    -------
    float
        The edf; ``σ̂²·edf/σ²`` is close to chi-square with that many degrees of freedom
        (NIST SP 1065 eq. 45).
    """
    if alpha not in _GR_TABLE2_D2:
        raise CalibInputError(f"alpha must be 0, -1 or -2 (rate noise power law), not {alpha!r}")
    m = int(m)
    big_m = float(n_phase - 2 * m)  # number of second differences, M = 1 + floor(S(N − L)/m)
    if m < 1 or big_m < 1:
        raise CalibInputError(f"m={m} needs at least {2 * m + 1} phase points, got {n_phase}")
    s = float(m)
    j = int(min(big_m, 3 * m))
    r = big_m / s
    if j <= _GR_JMAX:
        f = float(m) if 3 * m <= _GR_JMAX else math.inf
        sz0 = float(_gr_sz(np.array(0.0), f, alpha))
        inv = _gr_basic_sum(j, big_m, s, f, alpha) / (sz0**2 * big_m)
    elif r > 3.0:
        a0, a1 = _GR_TABLE2_D2[alpha]
        inv = (a0 - a1 / r) / r
    else:
        sz0 = float(_gr_sz(np.array(0.0), math.inf, alpha))
        inv = _gr_basic_sum(_GR_JMAX, _GR_JMAX, _GR_JMAX / r, math.inf, alpha) / (sz0**2 * _GR_JMAX)
    return 1.0 / inv


def overlapping_avar(rate: np.ndarray, odr_hz: float, ms: np.ndarray) -> np.ndarray:
    """Overlapping Allan variance of a rate record at factors ``ms`` (NIST SP 1065 eq. 11).

    Parameters
    ----------
    rate : ndarray (n,)
        Uniformly sampled rate (fractional-frequency data), any unit.
    odr_hz : float
        Sample rate, Hz.
    ms : ndarray of int
        Averaging factors, each in ``[1, n // 2]``.

    Returns
    -------
    ndarray, shaped like ``ms``
        ``σ²(τ = m/odr)`` in the rate's unit squared.
    """
    tau0 = 1.0 / odr_hz
    x = np.concatenate([[0.0], np.cumsum(np.asarray(rate, dtype=float)) * tau0])  # phase
    out = np.empty(len(ms))
    for i, m in enumerate(np.asarray(ms, dtype=np.int64)):
        d2 = x[2 * m :] - 2.0 * x[m : x.size - m] + x[: x.size - 2 * m]
        out[i] = np.dot(d2, d2) / (2.0 * (m * tau0) ** 2 * d2.size)
    return out


@dataclass(frozen=True)
class PhaseRecord:
    """A still record too long to hold, given as random access to its phase.

    The phase of axis ``j`` is ``x_0 = 0``, ``x_i = τ0 Σ_{k<i} y_k`` (the integrated rate, NIST
    SP 1065 §4 "phase data"), for ``i = 0 … n_samples``.

    Attributes
    ----------
    n_samples : int
        Rate samples per axis (one fewer than phase points).
    read : callable
        ``read(start, stop)`` returns the phase points ``[start, stop)`` as an array of shape
        ``(stop - start, A)``; the caller keeps them wherever it likes (a file, a memory map).
    """

    n_samples: int
    read: Callable[[int, int], np.ndarray]


def phase_blocks(blocks: Iterable[np.ndarray], odr_hz: float) -> Iterator[np.ndarray]:
    """Turn rate blocks into phase blocks, exactly as :func:`overlapping_avar` integrates.

    Parameters
    ----------
    blocks : iterable of ndarray (k, A)
        Consecutive rate samples.
    odr_hz : float
        Sample rate, Hz.

    Yields
    ------
    ndarray (k, A)
        The phase points after each sample of the block (the leading ``x_0 = 0`` is not
        yielded): a running sum carried across blocks, so the values equal those of one
        ``cumsum`` over the whole record bit for bit.
    """
    tau0 = 1.0 / scalar(odr_hz, "odr_hz", positive=True)
    carry = None
    for block in blocks:
        y = np.asarray(block, dtype=float)
        if y.ndim == 1:
            y = y[:, None]
        if y.shape[0] == 0:
            continue
        if carry is None:
            cs = np.cumsum(y, axis=0)
        else:
            cs = np.cumsum(np.concatenate([carry, y]), axis=0)[1:]
        carry = cs[-1:].copy()
        yield cs * tau0


def overlapping_avar_blocks(
    record: PhaseRecord, odr_hz: float, ms: np.ndarray, block: int = 1 << 16
) -> np.ndarray:
    """:func:`overlapping_avar` of a record held outside memory (NIST SP 1065 eq. 11).

    The second differences ``x_{k+2m} − 2 x_{k+m} + x_k`` are formed ``block`` at a time from
    three reads of the phase, so memory stays a few blocks whatever the record's length; the
    result equals :func:`overlapping_avar` of the whole record up to the order of summation
    (relative differences of order 1e-15).

    Parameters
    ----------
    record : PhaseRecord
    odr_hz : float
        Sample rate, Hz.
    ms : ndarray of int
        Averaging factors, each in ``[1, n // 2]``.
    block : int
        Second differences formed at a time.

    Returns
    -------
    ndarray (len(ms), A)
        ``σ²(τ = m/odr)``.
    """
    tau0 = 1.0 / odr_hz
    n_phase = record.n_samples + 1
    rows = []
    for m in np.asarray(ms, dtype=np.int64).tolist():
        count = n_phase - 2 * m
        acc = None
        for k in range(0, count, block):
            stop = min(count, k + block)
            d2 = record.read(k + 2 * m, stop + 2 * m) - 2.0 * record.read(k + m, stop + m)
            d2 += record.read(k, stop)
            part = np.einsum("ij,ij->j", d2, d2)
            acc = part if acc is None else acc + part
        rows.append(acc / (2.0 * (m * tau0) ** 2 * count))
    return np.array(rows)


def _edf_table(ms: np.ndarray, n: int) -> np.ndarray:
    out = np.empty((ms.size, 3))
    for i, m in enumerate(ms):
        for j, alpha in enumerate(_ALPHA):
            out[i, j] = edf_greenhall(alpha, int(m), n + 1)
    return out


def allan_deviation(
    rate: np.ndarray | PhaseRecord, odr_hz: float, *, m: np.ndarray | None = None
) -> AllanCurve:
    """Overlapping Allan deviation of each column of ``rate`` (IEEE Std 952, NIST SP 1065 eq. 11).

    Parameters
    ----------
    rate : array_like, shape (n,) or (n, A), or PhaseRecord
        A gap-free, uniformly sampled still record, rad/s; a :class:`PhaseRecord` for one too
        long to hold (computed by :func:`overlapping_avar_blocks` in bounded memory).
    odr_hz : float
        Its sample rate, Hz.
    m : array_like of int, optional
        Averaging factors; default two per octave from 1 up to ``n/4``.

    Returns
    -------
    AllanCurve
    """
    fs = scalar(odr_hz, "odr_hz", positive=True)
    if isinstance(rate, PhaseRecord):
        a = None
        n = rate.n_samples
        if n < _MIN_SAMPLES:
            raise CalibInputError(
                f"rate has {n} samples; an Allan deviation needs at least {_MIN_SAMPLES}"
            )
    else:
        a = _as_rate(rate)
        n = a.shape[0]
    if m is None:
        ms = _taus_m(n)
    else:
        ms = np.unique(np.asarray(m, dtype=np.int64).reshape(-1))
        if ms.size == 0 or ms[0] < 1 or ms[-1] > (n - 1) // 2:
            raise CalibInputError(f"m must be averaging factors in [1, {(n - 1) // 2}]")
    if a is None:
        adev = np.sqrt(overlapping_avar_blocks(rate, fs, ms))
    else:
        adev = np.sqrt(
            np.column_stack([overlapping_avar(a[:, j], fs, ms) for j in range(a.shape[1])])
        )
    return AllanCurve(
        tau_s=ms / fs, m=ms, adev=adev, odr_hz=fs, n_samples=n, edf=_edf_table(ms, n)
    )


@dataclass(frozen=True)
class NoiseFigure:
    """One noise coefficient per axis, read off the Allan deviation.

    Attributes
    ----------
    value : tuple of 3 float
    std : tuple of 3 float
        One-sigma uncertainty: half the width of the 68 % chi-square interval.
    lo95, hi95 : tuple of 3 float
        The 95 % interval (chi-square, so not symmetric where the estimate has few degrees
        of freedom, as rate random walk read at long averaging times has).
    tau_s : tuple of 3 float
        The averaging time it was read at, s.
    unit : str
    """

    value: tuple[float, ...]
    std: tuple[float, ...]
    lo95: tuple[float, ...]
    hi95: tuple[float, ...]
    tau_s: tuple[float, ...]
    unit: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "value": list(self.value),
            "std": list(self.std),
            "lo95": list(self.lo95),
            "hi95": list(self.hi95),
            "tau_s": list(self.tau_s),
            "unit": self.unit,
        }

    @classmethod
    def from_dict(cls, d: Any, name: str, unit: str) -> NoiseFigure:
        """Inverse of :meth:`to_dict`; raises :class:`CalibrationFormatError` naming the field."""
        if not isinstance(d, Mapping):
            raise CalibrationFormatError(f"{name!r} must be an object")
        vals = {}
        for key in ("value", "std", "lo95", "hi95", "tau_s"):
            v = d.get(key)
            ok = isinstance(v, list) and len(v) == 3
            ok = ok and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                for x in v
            )
            if not ok:
                raise CalibrationFormatError(f"'{name}.{key}' must be a list of 3 finite numbers")
            vals[key] = tuple(float(x) for x in v)
        if d.get("unit", unit) != unit:
            raise CalibrationFormatError(f"'{name}.unit' is {d.get('unit')!r}, expected {unit!r}")
        return cls(
            vals["value"], vals["std"], vals["lo95"], vals["hi95"], vals["tau_s"], unit
        )


UNIT_N = "rad/s/sqrt(Hz)"
UNIT_B = "rad/s"
UNIT_K = "rad/s/sqrt(s)"


@dataclass(frozen=True, eq=False)
class NoiseCharacterisation:
    """The noise figures of a gyro from a still record (``gyrocal-noise`` v1).

    Attributes
    ----------
    noise_density : NoiseFigure
        Angle random walk ``N``, rad/s/√Hz (Kalibr's ``gyroscope_noise_density``).
    bias_instability : NoiseFigure
        ``B``, rad/s: the flicker floor ``(0.664 B)²`` of the fitted model read at the τ where
        it is best determined (not the curve's minimum over 0.664; that is ``adev_min``).
    rate_random_walk : NoiseFigure
        ``K``, rad/s/√s (Kalibr's ``gyroscope_random_walk``, rad/s²/√Hz).
    tau_s : ndarray (M,)
    adev : ndarray (M, 3)
        The Allan deviation curve, rad/s.
    adev_lo, adev_hi : ndarray (M, 3)
        Its one-sigma chi-square interval (edf of the locally dominant noise term).
    fit : dict
        The three-term model's coefficients per axis: ``{"N": [3], "B": [3], "K": [3]}``.
    adev_min : dict
        The curve's minimum per axis, ``{"value": [3] rad/s, "tau_s": [3]}``; datasheets often
        quote ``value / 0.664`` as the bias instability.
    odr_hz : float
    n_samples : int
    sensor : dict
    temperature_c : float or None
    created, source : str or None
    """

    noise_density: NoiseFigure
    bias_instability: NoiseFigure
    rate_random_walk: NoiseFigure
    tau_s: np.ndarray
    adev: np.ndarray
    adev_lo: np.ndarray
    adev_hi: np.ndarray
    fit: dict[str, tuple[float, ...]]
    adev_min: dict[str, tuple[float, ...]]
    odr_hz: float
    n_samples: int
    sensor: dict[str, Any] = field(default_factory=dict)
    temperature_c: float | None = None
    created: str | None = None
    source: str | None = None

    @property
    def duration_s(self) -> float:
        """Length of the record, s."""
        return self.n_samples / self.odr_hz

    @property
    def white_std(self) -> np.ndarray:
        """Per-sample white-noise standard deviation at ``odr_hz``, ``N √odr``, rad/s."""
        return np.asarray(self.noise_density.value) * math.sqrt(self.odr_hz)

    @property
    def rate_random_walk_or_hi95(self) -> tuple[float, ...]:
        """``K`` per axis where the record resolves it, else its 95 % upper bound, rad/s/√s.

        What a Kalman filter's ``Q`` or a Kalibr file should take: an unresolved (near zero)
        ``K`` would make the bias look frozen.
        """
        fig = self.rate_random_walk
        return tuple(k if k > 0 else hi for k, hi in zip(fig.value, fig.hi95, strict=True))

    def with_meta(self, **fields: Any) -> NoiseCharacterisation:
        """A copy with ``sensor``, ``temperature_c``, ``created`` or ``source`` replaced."""
        allowed = {"sensor", "temperature_c", "created", "source"}
        bad = set(fields) - allowed
        if bad:
            raise CalibInputError(f"with_meta accepts {sorted(allowed)}, not {sorted(bad)}")
        d = {f: getattr(self, f) for f in self.__dataclass_fields__}
        d.update(fields)
        return NoiseCharacterisation(**d)

    def to_dict(self) -> dict[str, Any]:
        """The ``gyrocal-noise`` v1 document as a JSON-ready dict."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "method": METHOD,
            "odr_hz": self.odr_hz,
            "n_samples": self.n_samples,
            "duration_s": self.duration_s,
            "noise_density": self.noise_density.to_dict(),
            "bias_instability": self.bias_instability.to_dict(),
            "rate_random_walk": self.rate_random_walk.to_dict(),
            "fit": {k: list(v) for k, v in self.fit.items()},
            "adev_min": {k: list(v) for k, v in self.adev_min.items()},
            "allan": {
                "tau_s": self.tau_s.tolist(),
                "adev": self.adev.tolist(),
                "adev_lo": self.adev_lo.tolist(),
                "adev_hi": self.adev_hi.tolist(),
            },
            "sensor": dict(self.sensor),
            "temperature_c": self.temperature_c,
            "created": self.created,
            "source": self.source,
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> NoiseCharacterisation:
        """Read a ``gyrocal-noise`` v1 document.

        Raises
        ------
        CalibrationFormatError
            If the format or version is wrong, or a field is missing or malformed (named).
        """
        if not isinstance(doc, Mapping):
            raise CalibrationFormatError("a noise document must be a JSON object")
        if doc.get("format") != FORMAT:
            raise CalibrationFormatError(
                f"not a gyrocal noise document: 'format' is {doc.get('format')!r}, "
                f"expected {FORMAT!r}"
            )
        if doc.get("version") != VERSION or isinstance(doc.get("version"), bool):
            raise CalibrationFormatError(
                f"noise document version {doc.get('version')!r} is not supported (this gyrocal "
                f"reads version {VERSION})"
            )
        odr = doc.get("odr_hz")
        if isinstance(odr, bool) or not isinstance(odr, (int, float)) or not 0 < odr < math.inf:
            raise CalibrationFormatError("'odr_hz' must be a positive number")
        n = doc.get("n_samples")
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise CalibrationFormatError("'n_samples' must be a positive integer")
        allan = doc.get("allan")
        if not isinstance(allan, Mapping):
            raise CalibrationFormatError("'allan' must be an object")
        try:
            tau = np.asarray(allan["tau_s"], dtype=float)
            arrs = [np.asarray(allan[k], dtype=float) for k in ("adev", "adev_lo", "adev_hi")]
        except (KeyError, TypeError, ValueError):
            raise CalibrationFormatError(
                "'allan' must hold 'tau_s' [M] and 'adev', 'adev_lo', 'adev_hi' [M][3] numbers"
            ) from None
        if tau.ndim != 1 or any(a.shape != (tau.size, 3) for a in arrs):
            raise CalibrationFormatError("'allan' arrays must be tau_s [M] and [M][3] curves")
        fit = doc.get("fit") or {}
        adev_min = doc.get("adev_min") or {}
        for name, v in (("fit", fit), ("adev_min", adev_min)):
            ok = isinstance(v, Mapping) and all(
                isinstance(x, list) and len(x) == 3 and all(
                    isinstance(e, (int, float)) and not isinstance(e, bool) for e in x
                )
                for x in v.values()
            )
            if not ok:
                raise CalibrationFormatError(f"{name!r} must map names to lists of 3 numbers")
        sensor = doc.get("sensor") or {}
        if not isinstance(sensor, Mapping):
            raise CalibrationFormatError("'sensor' must be an object")
        temp = doc.get("temperature_c")
        if temp is not None and (
            isinstance(temp, bool) or not isinstance(temp, (int, float)) or not math.isfinite(temp)
        ):
            raise CalibrationFormatError("'temperature_c' must be a number or null")
        return cls(
            noise_density=NoiseFigure.from_dict(doc.get("noise_density"), "noise_density", UNIT_N),
            bias_instability=NoiseFigure.from_dict(
                doc.get("bias_instability"), "bias_instability", UNIT_B
            ),
            rate_random_walk=NoiseFigure.from_dict(
                doc.get("rate_random_walk"), "rate_random_walk", UNIT_K
            ),
            tau_s=tau,
            adev=arrs[0],
            adev_lo=arrs[1],
            adev_hi=arrs[2],
            fit={str(k): tuple(float(x) for x in v) for k, v in fit.items()},
            adev_min={str(k): tuple(float(x) for x in v) for k, v in adev_min.items()},
            odr_hz=float(odr),
            n_samples=n,
            sensor=dict(sensor),
            temperature_c=None if temp is None else float(temp),
            created=doc.get("created"),
            source=doc.get("source"),
        )


def _basis(tau: np.ndarray) -> np.ndarray:
    """Columns of the Allan-variance model in (N², (0.664 B)², K²): 1/τ, 1, τ/3."""
    return np.column_stack([1.0 / tau, np.ones_like(tau), tau / 3.0])


def _fit_axis(avar: np.ndarray, tau: np.ndarray, edf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted NNLS of the three-term model; returns (coefficients², per-τ edf used)."""
    A = _basis(tau)
    model = avar.copy()
    e = edf[:, 0]
    coef = np.zeros(3)
    for _ in range(4):
        w = np.sqrt(e / 2.0) / model  # 1 / std(σ̂²) with std = σ²·√(2/edf)
        coef, _ = nnls(A * w[:, None], avar * w)
        terms = A * coef[None, :]
        model = np.maximum(terms.sum(axis=1), 1e-300)
        e = edf[np.arange(tau.size), np.argmax(terms, axis=1)]
    return coef, e


def _chi2_interval(avar: float, edf: float, level: float) -> tuple[float, float]:
    """Interval of a true Allan variance given its estimate and edf (NIST SP 1065 eq. 45)."""
    q = (1.0 - level) / 2.0
    return avar * edf / chdtri(edf, q), avar * edf / chdtri(edf, 1.0 - q)


def _read_off(
    avar: np.ndarray,
    tau: np.ndarray,
    edf: np.ndarray,
    coef: np.ndarray,
    j: int,
    usable: np.ndarray,
) -> tuple[float, float, float, float, float]:
    """Read term ``j`` (0: N, 1: flicker floor, 2: K) at its best-determined τ.

    Returns ``(value, std, lo95, hi95, tau)``: the coefficient from that τ's Allan variance with
    the other fitted terms subtracted, and the chi-square intervals of that one estimate carried
    through (``std`` is half the width of the 68 % interval).
    """
    A = _basis(tau)
    terms = A * coef[None, :]
    model = np.maximum(terms.sum(axis=1), 1e-300)
    # Predicted std of this term's squared coefficient if read at each τ (from the model).
    s2 = np.sqrt(2.0 / edf) * model / A[:, j]
    s2 = np.where(usable, s2, np.inf)
    i = int(np.argmin(s2))
    others = model[i] - terms[i, j]

    def coef_of(v: float) -> float:
        return math.sqrt(max((v - others) / A[i, j], 0.0))

    value = coef_of(float(avar[i]))
    lo68, hi68 = (coef_of(v) for v in _chi2_interval(float(avar[i]), float(edf[i]), _ONE_SIGMA))
    lo95, hi95 = (coef_of(v) for v in _chi2_interval(float(avar[i]), float(edf[i]), 0.95))
    return value, (hi68 - lo68) / 2.0, lo95, hi95, float(tau[i])


#: ``N`` is read at τ = 1 s (IEEE Std 952's reading of the slope −½ line) when the curve has a
#: point within this factor of 1 s where white noise dominates.
_ONE_SECOND_FACTOR = math.sqrt(2.0)
#: Share of the fitted model the white-noise term must have at a τ for that τ to be on the
#: white-noise slope.
_WHITE_SHARE = 0.5


def _read_white(avar: np.ndarray, tau: np.ndarray, edf: np.ndarray, coef: np.ndarray,
                usable: np.ndarray) -> tuple[float, float, float, float, float]:
    """``N`` from the white-noise slope of the curve, with an interval that covers its shape.

    The white-noise slope is the usable τ where ``N²/τ`` is at least :data:`_WHITE_SHARE` of
    the fitted model. ``N`` is read (as :func:`_read_off`) at the point nearest τ = 1 s when one
    lies within :data:`_ONE_SECOND_FACTOR` of it, the IEEE reading, clear of the correlation and
    the short-τ bumps (vibration, a low-pass filter) a real curve has near ten samples; else at
    the best-determined τ of the slope. The 95 % interval is that one estimate's chi-square
    interval widened to hold ``N`` read at every other point of the slope: where the curve
    departs from slope −½ (real gyros: 1.25–1.9× at ten samples on some BROAD axes), the
    departure is part of the uncertainty, not hidden by the statistics of one point.
    """
    A = _basis(tau)
    terms = A * coef[None, :]
    model = np.maximum(terms.sum(axis=1), 1e-300)
    white = usable & (terms[:, 0] >= _WHITE_SHARE * model)
    if not np.any(white):
        return _read_off(avar, tau, edf, coef, 0, usable)
    near = white & (np.abs(np.log(tau)) <= math.log(_ONE_SECOND_FACTOR))
    pick = np.zeros_like(white)
    if np.any(near):
        pick[int(np.argmin(np.where(near, np.abs(np.log(tau)), np.inf)))] = True
    else:
        pick = white
    value, std, lo95, hi95, t = _read_off(avar, tau, edf, coef, 0, pick)
    others = model - terms[:, 0]
    along = np.sqrt(np.maximum(avar - others, 0.0) * tau)[white]
    return value, std, min(lo95, float(along.min())), max(hi95, float(along.max())), t


#: Decades of averaging time the curve must span above the shortest τ read for ``N``, so that the
#: three terms of the model (slopes −½, 0, +½) can be told apart.
_SPAN_DECADES = 2


def min_still_samples(odr_hz: float, min_tau_s: float | None = None) -> int:
    """Samples a still record needs for :func:`characterise_noise` to separate its three terms.

    The curve's averaging factors run two per octave up to ``n/4`` (:func:`_taus_m`, Stable32's
    stop ratio for the overlapping Allan deviation) and must span ``_SPAN_DECADES`` decades
    above the shortest averaging time ``N`` is read at (default 10 samples), to the grid's own
    resolution: its top point must lie within one grid step (half an octave) below
    ``10^decades · m_min``. Records that give the same grid give the same curve points, so the
    count is the least ``n`` whose grid holds that point: 2900 samples for ``m_min = 10``
    (top point 724, 1.86 decades), where ``n ≥ 4 · 10^decades · m_min`` = 4000 asked for a point
    (1000) the grid never has below 4096 samples and refused records, such as a 20 s session at
    200 Hz (3998 samples), whose curves equal those it accepted.

    Parameters
    ----------
    odr_hz : float
        Sample rate, Hz.
    min_tau_s : float, optional
        Shortest averaging time used for ``N``, s (default ``10/odr_hz``).

    Returns
    -------
    int
    """
    fs = scalar(odr_hz, "odr_hz", positive=True)
    m_min = 10 if min_tau_s is None else max(1, math.ceil(min_tau_s * fs - 1e-9))
    per_octave = 2  # as _taus_m
    span = math.log2(10**_SPAN_DECADES * m_min)  # octaves
    top = math.ceil(per_octave * span - 1 - 1e-9) / per_octave  # the grid point a step below
    return 4 * math.ceil(2.0**top)


def characterise_noise(
    rate: np.ndarray | PhaseRecord,
    odr_hz: float,
    *,
    min_tau_s: float | None = None,
    m: np.ndarray | None = None,
) -> NoiseCharacterisation:
    """Angle random walk, bias instability and rate random walk of a still record.

    Parameters
    ----------
    rate : array_like, shape (n, 3), or PhaseRecord
        A gap-free, uniformly sampled record of the sensor at rest, rad/s, at a steady
        temperature (a temperature drift shows up as rate random walk and rate ramp); a
        :class:`PhaseRecord` of three axes for a record too long to hold in memory.
    odr_hz : float
        Its sample rate, Hz.
    min_tau_s : float, optional
        Shortest averaging time used to read ``N`` (default 10 samples, which keeps clear of
        the correlation a digital low-pass filter puts between neighbouring samples).
    m : array_like of int, optional
        Averaging factors of the curve (see :func:`allan_deviation`).

    Returns
    -------
    NoiseCharacterisation
        ``sensor``, ``temperature_c``, ``created`` and ``source`` are left empty: set them with
        :meth:`NoiseCharacterisation.with_meta`.

    Notes
    -----
    See the module docstring for the method (IEEE Std 952-1997 Annex C).
    """
    a = rate if isinstance(rate, PhaseRecord) else _as_rate(rate)
    if not isinstance(a, PhaseRecord) and a.shape[1] != 3:
        raise CalibInputError(f"rate must have shape (n, 3), got {a.shape}")
    curve = allan_deviation(a, odr_hz, m=m)
    if curve.adev.shape[1] != 3:
        raise CalibInputError(f"rate must have shape (n, 3), got {curve.adev.shape[1]} axes")
    fs = curve.odr_hz
    tau = curve.tau_s
    min_tau = 10.0 / fs if min_tau_s is None else scalar(min_tau_s, "min_tau_s", nonneg=True)
    need = min_still_samples(fs, min_tau)
    if curve.n_samples < need or tau.size < 3 or np.count_nonzero(tau >= min_tau) < 2:
        raise CalibInputError(
            f"the still record is too short for noise figures: {curve.n_samples} samples "
            f"({curve.n_samples / fs:.3g} s at {fs:g} Hz), and separating white noise, bias "
            f"instability and rate random walk needs the Allan curve to span {_SPAN_DECADES} "
            f"decades of averaging time above {min_tau:.3g} s, i.e. at least {need} samples "
            f"({need / fs:.3g} s); record the sensor still for longer (many minutes for bias "
            "instability)"
        )
    usable_n = tau >= min_tau
    out: dict[str, list[tuple[float, ...]]] = {"N": [], "B": [], "K": []}
    fit: dict[str, list[float]] = {"N": [], "B": [], "K": []}
    adev_min: dict[str, list[float]] = {"value": [], "tau_s": []}
    lo = np.empty_like(curve.adev)
    hi = np.empty_like(curve.adev)
    for ax in range(3):
        avar = curve.adev[:, ax] ** 2
        coef, e_used = _fit_axis(avar, tau, curve.edf)
        fit["N"].append(math.sqrt(coef[0]))
        fit["B"].append(math.sqrt(coef[1]) / FLICKER_FLOOR)
        fit["K"].append(math.sqrt(coef[2]))
        edf_n = curve.edf[:, 0]
        edf_k = curve.edf[:, 2]
        out["N"].append(_read_white(avar, tau, edf_n, coef, usable_n))
        out["K"].append(_read_off(avar, tau, edf_k, coef, 2, np.ones_like(usable_n)))
        edf_b = curve.edf[:, 1]
        vb, sb, lob, hib, tb = _read_off(avar, tau, edf_b, coef, 1, np.ones_like(usable_n))
        f = FLICKER_FLOOR
        out["B"].append((vb / f, sb / f, lob / f, hib / f, tb))
        i = int(np.argmin(curve.adev[:, ax]))
        adev_min["value"].append(float(curve.adev[i, ax]))
        adev_min["tau_s"].append(float(tau[i]))
        lo_ax, hi_ax = curve.interval(e_used[:, None])
        lo[:, ax], hi[:, ax] = lo_ax[:, ax], hi_ax[:, ax]

    def figure(key: str, unit: str) -> NoiseFigure:
        vals = out[key]
        return NoiseFigure(
            value=tuple(v[0] for v in vals),
            std=tuple(v[1] for v in vals),
            lo95=tuple(v[2] for v in vals),
            hi95=tuple(v[3] for v in vals),
            tau_s=tuple(v[4] for v in vals),
            unit=unit,
        )

    return NoiseCharacterisation(
        noise_density=figure("N", UNIT_N),
        bias_instability=figure("B", UNIT_B),
        rate_random_walk=figure("K", UNIT_K),
        tau_s=tau,
        adev=curve.adev,
        adev_lo=lo,
        adev_hi=hi,
        fit={k: tuple(v) for k, v in fit.items()},
        adev_min={k: tuple(v) for k, v in adev_min.items()},
        odr_hz=fs,
        n_samples=curve.n_samples,
    )
