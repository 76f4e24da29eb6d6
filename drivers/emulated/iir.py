"""The emulators' low-order IIR filters, without ``scipy.signal``.

The emulated servos' tracking lags and ripple noise, the chips' output filters and the coloured
noise's long runs are first- and second-order recursions. ``scipy.signal.lfilter`` ran them, but
importing ``scipy.signal`` costs about a second of CPU (it imports ``scipy.stats`` and parses
every function's docstring), more than the filtering itself in a calibration. :func:`lfilter`
is the same Direct Form II transposed recursion in the same arithmetic order as SciPy's
``_linear_filter`` (``y = z₀ + b₀x``; ``zₖ = zₖ₊₁ + bₖ₊₁x − aₖ₊₁y``; the last
``z = b_N x − a_N y``, coefficients normalised by ``a₀`` and padded with zeros to one length),
so it gives the same numbers to the last bit; ``tests/drivers/test_emulated_iir.py`` checks it
against SciPy.

The recursion runs in SciPy's own compiled kernel where it can be had without that import: the
``_sigtools`` extension module of ``scipy.signal`` holds ``_linear_filter``, the DF2T loop
``scipy.signal.lfilter`` calls, and it loads on its own from the installed package's folder in a
few milliseconds (numpy's C API is all it needs). A pure-Python loop of the same arithmetic runs
where it cannot be loaded (:func:`_kernel`); it is twenty times slower (0.75 µs a sample and
column), which was a second of CPU per emulated calibration (issue 25).
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["compiled", "lfilter"]

#: SciPy's compiled DF2T kernel once looked for: ``None`` not yet, ``False`` not found.
_KERNEL: Any = None


def _kernel() -> Callable[..., Any] | None:
    """``scipy.signal._sigtools._linear_filter`` loaded from its extension module alone (not
    through ``scipy.signal``, whose import costs a second), or ``None`` where the installed
    SciPy has no such module or it does not load."""
    global _KERNEL
    if _KERNEL is None:
        _KERNEL = False
        try:
            scipy_spec = importlib.util.find_spec("scipy")
            folders = [f"{d}/signal" for d in (scipy_spec.submodule_search_locations or ())] \
                if scipy_spec is not None else []
            spec = importlib.machinery.PathFinder.find_spec("_sigtools", folders)
            if spec is not None and spec.loader is not None:
                module = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(module)
                _KERNEL = getattr(module, "_linear_filter", False)
        except Exception:  # a private module: any SciPy that loads it differently falls back
            _KERNEL = False
    return _KERNEL or None


def compiled() -> bool:
    """Whether :func:`lfilter` runs in SciPy's compiled kernel here (else in its Python loop,
    twenty times slower: a caller with a faster loop of its own for a special case keeps it)."""
    return _kernel() is not None


def lfilter(b: Sequence[float], a: Sequence[float], x: np.ndarray,
            zi: np.ndarray | Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Filter ``x`` along its first axis with the transfer function ``b / a`` (orders up to
    2), from the state ``zi`` (zeros when None); returns ``(y, zf)``.

    Parameters
    ----------
    b, a : sequence of float
        Numerator and denominator, ``a[0] != 0``; ``max(len(a), len(b))`` at most 3.
    x : ndarray (n,) or (n, m)
        The input; each column is filtered on its own.
    zi : array_like (order,) or (order, m), optional
        The initial state, as ``scipy.signal.lfilter``'s ``zi`` with ``axis=0``.
    """
    n = max(len(a), len(b))
    if not 2 <= n <= 3:
        raise ValueError(f"orders 1 and 2 only, got b {list(b)!r}, a {list(a)!r}")
    bb = [float(v) for v in b] + [0.0] * (n - len(b))
    aa = [float(v) for v in a] + [0.0] * (n - len(a))
    a0 = aa[0]
    bb, aa = [v / a0 for v in bb], [v / a0 for v in aa]
    x = np.asarray(x, dtype=float)
    cols = x.reshape(x.shape[0], -1)
    z = (np.zeros((n - 1, cols.shape[1])) if zi is None
         else np.asarray(zi, dtype=float).reshape(n - 1, cols.shape[1]))
    kernel = _kernel()
    if kernel is not None and cols.shape[0]:
        try:
            y, zf = kernel(np.array(bb), np.array(aa), cols, 0, z)
        except (TypeError, ValueError):  # a SciPy whose private kernel takes other arguments
            global _KERNEL
            _KERNEL = False
        else:
            return y.reshape(x.shape), zf.reshape(np.shape(zi) if zi is not None else zf.shape)
    y = np.empty_like(cols)
    zf = np.empty_like(z)
    for j in range(cols.shape[1]):
        ys, state = (_first if n == 2 else _second)(bb, aa, cols[:, j].tolist(),
                                                    z[:, j].tolist())
        y[:, j] = ys
        zf[:, j] = state
    return y.reshape(x.shape), zf.reshape(np.shape(zi) if zi is not None else zf.shape)


def _first(b: list[float], a: list[float], x: list[float], z: list[float]
           ) -> tuple[list[float], list[float]]:
    b0, b1, a1 = b[0], b[1], a[1]
    z0 = z[0]
    out = []
    append = out.append
    for xn in x:
        yn = z0 + b0 * xn
        z0 = xn * b1 - yn * a1
        append(yn)
    return out, [z0]


def _second(b: list[float], a: list[float], x: list[float], z: list[float]
            ) -> tuple[list[float], list[float]]:
    b0, b1, b2, a1, a2 = b[0], b[1], b[2], a[1], a[2]
    z0, z1 = z
    out = []
    append = out.append
    for xn in x:
        yn = z0 + b0 * xn
        z0 = z1 + xn * b1 - yn * a1
        z1 = xn * b2 - yn * a2
        append(yn)
    return out, [z0, z1]
