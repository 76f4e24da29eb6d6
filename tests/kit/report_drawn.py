"""What ``gyrocal report`` draws into ``residuals.png``, for tests that compare it with the fit:
the report's own drawing step (``kit.report_plots._draw``) run for that one plot, stopped when
it hands the residuals to the figure (nothing is rendered: the numbers are the test)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


class _Handed(Exception):
    """Carries the residuals ``_draw`` handed to the figure."""


def drawn_residuals(rec: Any, cal: Any, ex: Any, out: Path, monkeypatch: Any) -> Any:
    """The :class:`~gyrocal.kit.report_plots.Residuals` the report draws for ``rec`` and
    ``cal`` with the windows ``ex`` (as the fit judged them: ``kit.pipeline.judged_windows``)."""
    from gyrocal.kit import report_plots as rp
    from gyrocal.kit.plots import require_matplotlib

    def hand_over(plt: Any, res: Any, cal: Any, jig: str) -> Any:
        raise _Handed(res)

    monkeypatch.setattr(rp, "_residuals_plot", hand_over)
    plan = next(p for p in rp.plan_report(rec, ex) if p.kind == "residuals")
    try:
        rp._draw(require_matplotlib(), plan, Path(out), rec, cal, ex, None, {},
                 rp.window_axes(ex, cal, rec.manifest), {}, False)
    except _Handed as handed:
        return handed.args[0]
    raise AssertionError("the report drew no residuals")
