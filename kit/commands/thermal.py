"""``gyrocal thermal``: a thermal model from calibrations at several die temperatures."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

HELP = "thermal: fit bias and scale against die temperature (warm-up runs or calibration files)"
DESCRIPTION = (
    "Fit the sensor's bias (a polynomial in the die temperature, its order chosen by BIC) and "
    "its scale or full matrix (linear) against temperature, with uncertainties and a χ² "
    "consistency check, over the temperature range covered; the result is a Calibration "
    "document with a temperature_model that apply, export and track use. Either give "
    "Calibration JSON files or directories of them (e.g. what 'gyrocal history export' wrote), "
    "or run the jig (--sim: the emulated one): the calibration protocol runs --runs times back "
    "to back while the die warms, each run written to DIR/run-NN/, the model to "
    "DIR/calibration.json. With --sim the emulated die warms by itself from power-on (and with "
    "--sim-temperature the ambient moves too). --static S fits the flight stacks' way instead, "
    "for comparison: one spin calibration, then the sensor still for S seconds, bias only. "
    "Exits 3 if the "
    "calibrations are not consistent with their stated uncertainties."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    from gyrocal.kit.commands.calibrate import add_common_jig_arguments

    p.add_argument("calibrations", nargs="*", metavar="CAL",
                   help="Calibration JSON files, or directories searched for them (without "
                        "these, the jig runs the protocol: give --sim or a configured jig)")
    add_common_jig_arguments(p)
    p.add_argument("--runs", type=int, default=8, metavar="N",
                   help="calibrations back to back on the jig (default 8)")
    p.add_argument("--wait", type=float, default=0.0, metavar="S",
                   help="seconds between runs, servos off (default 0)")
    p.add_argument("--static", type=float, metavar="S",
                   help="instead of repeated spins: one spin calibration, then the sensor "
                        "still for S seconds while it warms; bias(T) only (PX4/ArduPilot)")
    p.add_argument("--out", metavar="PATH",
                   help="with the jig: the run directory (default ./gyrocal-thermal-"
                        "YYYYmmdd-HHMMSS); with files: where to write the document")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.add_argument("--allow-implausible", action="store_true",
                   help="keep runs whose scale or bias is implausible (normally exit 6)")
    p.add_argument("--json", action="store_true", help="print the Calibration document")
    p.add_argument("--quiet", action="store_true", help="no progress display")


def _table(cal: Any, runs: list[tuple[str, Any]], truth: Any = None) -> str:
    """The model in words and numbers, then the calibrations it was fitted on."""
    import numpy as np

    from gyrocal.kit.thermal import truth_at

    m = cal.temperature_model
    lo, hi = m.range_c
    crit = m.criterion or {}
    lines = [f"gyrocal thermal model ({m.kind}, {m.points} points over {lo:.2f}…{hi:.2f} °C, "
             f"reference {m.reference_c:.2f} °C)",
             f"bias(T): order {m.bias_order} chosen by {crit.get('name', '?')} "
             f"(scores {', '.join(f'{k}: {v:.1f}' for k, v in crit.get('scores', {}).items())})",
             "", "axis   " + "".join(f"   c{k} (rad/s/°C^{k})     ± std" for k in
                                      range(m.bias_order + 1))]
    for j in range(3):
        std = np.sqrt(np.diag(m.bias_coeffs_covariance[j]))
        lines.append(f"{'xyz'[j]}      " + "".join(
            f"{m.bias_coeffs[j, k]:+20.6e} {std[k]:9.2e}" for k in range(m.bias_order + 1)))
    if m.gain_coeffs is not None:
        slope = np.diag(m.gain_coeffs[1])
        sstd = np.diag(m.gain_coeffs_std[1]) if m.gain_coeffs_std is not None else [np.nan] * 3
        lines += ["", "scale change per °C: " + ", ".join(
            f"{'xyz'[j]} {slope[j]:+.3e} ± {sstd[j]:.1e}" for j in range(3))]
    c = m.consistency
    if c is not None:
        verdict = "consistent" if c.ok else "NOT consistent (uncertainties scaled to the scatter)"
        lines += ["", f"consistency: {verdict} with the calibrations' uncertainties "
                      f"(chi2 = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g})"]
    lines += ["", "calibration                         T °C      bias x      bias y      bias z"
              + ("   err vs truth" if truth is not None else "")]
    for name, k in runs:
        b = np.asarray(k.bias)
        row = f"{name[-32:]:32s} {k.temperature_c:7.2f} " + " ".join(f"{x:+11.6f}" for x in b)
        tt = truth_at(truth, k.temperature_c)
        if tt is not None:
            row += f"   {np.max(np.abs(b - np.asarray(tt['bias']))):.1e}"
        lines.append(row)
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from pathlib import Path

    from gyrocal.kit.errors import InputError
    from gyrocal.kit.recording import now_iso
    from gyrocal.kit.thermal import collect_calibrations, fit_calibrations, thermal_calibration

    jig_mode = not args.calibrations
    if not jig_mode and (args.sim or args.static is not None):
        raise InputError("give calibration files, or run the jig (--sim, --static), not both")
    if args.wait < 0 or (args.static is not None and not args.static > 0):
        raise InputError("--wait must be >= 0 and --static a positive number of seconds")
    if not (1 if args.static is not None else 2) <= args.runs <= 1000:
        raise InputError(f"--runs must be 2..1000 (a thermal model needs calibrations at two "
                         f"temperatures at least; 5 or more let it find a curvature), got "
                         f"{args.runs}")
    truth = None
    if jig_mode:
        from gyrocal.kit.jig import load_cli_config, output_dir
        from gyrocal.kit.thermal import thermal_on_jig

        if args.sim and args.sim_temperature is None and args.sim_self_heating is None:
            from gyrocal.drivers.emulated.thermal import SELF_HEATING_C, SELF_HEATING_TAU_S

            # a thermal run on the emulated jig always has the warming die
            args.sim_self_heating = f"{SELF_HEATING_C:g}:{SELF_HEATING_TAU_S:g}"
        cfg = load_cli_config(args)
        out, work = output_dir(args)
        cal, runs, truth = thermal_on_jig(cfg, args, out, work, quiet=args.quiet)
    else:
        found = collect_calibrations(args.calibrations)
        model = fit_calibrations([c for _, c in found])
        cal = thermal_calibration([c for _, c in found], model,
                                  source=", ".join(args.calibrations), created=now_iso())
        runs = found
        out = None
        if args.out:
            from gyrocal.kit.fileio import emit_text

            emit_text(cal.to_json() + "\n", Path(args.out), force=args.force)
    if args.json:
        json.dump(cal.to_dict(), sys.stdout, indent=2)
        print()
    else:
        print(_table(cal, runs, truth))
        if out is not None:
            print(f"\nwrote {out / 'calibration.json'} and the runs in {out}/")
    c = cal.temperature_model.consistency
    return 3 if c is not None and not c.ok else 0
