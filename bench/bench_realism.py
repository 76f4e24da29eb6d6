"""How close the emulated hardware is to the chips (issue: emulated hardware third-party clients
cannot tell from the chips).

1. Bus time on the wall clock: an SMBus byte write (29 bit times) on :class:`EmulatedSMBus` with
   the system clock, against the time the bus speed implies (72.5 µs at 400 kHz).
2. The LSM9DS1 gyro bandwidth through the driver: the gain of the emulated chip at each
   cutoff of ST Table 47 (−3 dB = 0.7071 expected), for the LPF2 path the driver selects.
3. Third-party clients run unmodified against the emulators: which pass, which fail and why
   (the test suite's ``tests/drivers/test_third_party_clients.py``, run here with ``-rA``).

4. The cost of each realism effect of the emulated sensor (``gyrocal calibrate --sim --protocol
   full --sim-cross-axis 0.02``): every effect alone, none, and all, on the same sensors
   (``--seeds=N``, default 30): RMS errors of the fitted scale (diagonal of A), cross-axis
   (off-diagonal) and bias against the emulator's truth, the RMS of the bias error in its own σ,
   and how many fits pass the χ² consistency test.

   Each recording is fitted twice, without the g-sensitivity term and with it (the default),
   and the table gives the ratio; the last column is G's error in its own σ.

5. ``--independent``: g-sensitivity on the independent generator's recordings
   (tests/kit/contract_fullmodel_recording.py), ``--seeds`` of them.

Usage: ``python -m bench realism [--quick] [--seeds=N] [--effects-only] [--cases=all,none,...]
[--independent]``.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench.table import print_table


class _RegisterFile:
    """A minimal register device: a pointer and 256 bytes."""

    def __init__(self) -> None:
        self.regs = bytearray(256)
        self.ptr = 0

    def i2c_ack(self) -> int | None:
        return None

    def i2c_write(self, data: bytes) -> None:
        self.ptr = data[0]
        for b in data[1:]:
            self.regs[self.ptr] = b
            self.ptr = (self.ptr + 1) & 0xFF

    def i2c_read(self, length: int) -> bytes:
        out = bytes(self.regs[(self.ptr + i) & 0xFF] for i in range(length))
        self.ptr = (self.ptr + length) & 0xFF
        return out


def bus_timing(calls: int) -> None:
    from gyrocal.drivers.clock import SystemClock
    from gyrocal.drivers.emulated.smbus import EmulatedSMBus

    rows = []
    for hz in (100_000, 400_000, 1_000_000):
        bus = EmulatedSMBus(SystemClock(), bus_hz=hz)
        bus.attach(0x50, _RegisterFile())
        d = np.empty(calls)
        for i in range(calls):
            t0 = time.perf_counter()
            bus.write_byte_data(0x50, 1, 2)
            d[i] = time.perf_counter() - t0
        d *= 1e6
        rows.append([f"{hz / 1000:g} kHz", 29 / hz * 1e6, float(np.median(d)),
                     float(np.percentile(d, 90)), float(d.mean())])
    print_table(["bus", "nominal µs", "median µs", "p90 µs", "mean µs"], rows,
                title=f"SMBus byte write on the wall clock ({calls} calls each; the mean "
                      "includes the host's scheduling)")


def lsm_bandwidth() -> None:
    from gyrocal.drivers.clock import VirtualClock
    from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
    from gyrocal.drivers.emulated.motion import FunctionMotion
    from gyrocal.drivers.imu import open_imu
    from gyrocal.drivers.imu.chips import LSM9DS1_BW_G_CUTOFF_HZ

    amp = 200 * math.pi / 180
    rows = []
    for odr, cutoffs in LSM9DS1_BW_G_CUTOFF_HZ.items():
        for fc in sorted(set(cutoffs)):
            if fc > odr / 2:
                continue
            clock = VirtualClock()
            motion = FunctionMotion(lambda t, f=fc: np.column_stack(
                [amp * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]))
            bus, addr = make_emulated_imu("lsm9ds1", clock, motion,
                                          SensorTruth(),  # typical noise: a live gyro
                                          subsamples=1)
            reader = open_imu("lsm9ds1", bus, addr, clock=clock, range_dps=500, odr_hz=odr,
                              lowpass_hz=fc)
            reader.start()
            t, g = [], []
            while clock.monotonic() < 1.5:
                clock.sleep(0.01)
                b = reader.read()
                t.append(b.t)
                g.append(b.rate[:, 0])
            tt, gg = np.concatenate(t), np.concatenate(g)
            keep = tt > tt[0] + 0.7
            basis = np.column_stack([np.sin(2 * np.pi * fc * tt[keep]),
                                     np.cos(2 * np.pi * fc * tt[keep])])
            coef, *_ = np.linalg.lstsq(basis, gg[keep], rcond=None)
            rows.append([odr, fc, reader.info.lowpass_hz, float(np.hypot(*coef)) / amp])
    print_table(["ODR Hz", "Table 47 cutoff Hz", "driver reports Hz", "gain at cutoff"], rows,
                title="LSM9DS1 gyro bandwidth through the driver (0.7071 = −3 dB)")


def clients() -> None:
    test = Path(__file__).resolve().parent.parent / "tests/drivers/test_third_party_clients.py"
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider",
                          str(test)], capture_output=True, text=True, check=False)
    rows = []
    for line in run.stdout.splitlines():
        for status in ("PASSED", "FAILED", "SKIPPED", "ERROR"):
            if line.startswith(status + " "):
                rest = line[len(status) + 1:]
                name, _, why = rest.partition(" - ")
                rows.append([name.split("::")[-1], status, why.strip()[:70]])
    print_table(["client test", "result", "why"], rows,
                title="Third-party clients, unmodified, against the emulators")


def _errors(fit, C: np.ndarray, t: dict, Gt: np.ndarray | None) -> dict:
    """A fit's errors against the truth: scale (diagonal of A), free cross-axis terms, bias,
    bias error in its σ, χ², and (where fitted and true) G's error in its σ."""
    dA = fit.matrix - C
    db = fit.bias - np.asarray(t["bias"])
    bstd = np.sqrt(np.diag(fit.covariance))[9:12]
    off = ~np.eye(3, dtype=bool) & (np.abs(C) > 0)  # the free off-diagonal terms
    out = {"scale": np.diag(dA), "cross": dA[off], "bias": db, "bias_z": db / bstd,
           "ok": bool(fit.consistency.ok), "g_z": np.zeros(0)}
    if fit.g_sensitivity is not None and Gt is not None:
        # the model's G takes f in the calibration's frame: G = −G_true Qᵀ, Q = A C_sensing
        out["g_z"] = ((fit.g_sensitivity - t["_G_model"])
                      / np.sqrt(np.diag(fit.g_sensitivity_cov)).reshape(3, 3)).ravel()
    return out


def _effect_run(job: tuple[int, str]) -> dict:
    """One emulated calibration with only the effects named in ``job[1]`` on ("none", "all",
    one effect, or "all but E1 & E2"), fitted with and without the g-sensitivity term: each
    fit's errors against the manifest's truth."""
    import io
    import tempfile
    from contextlib import redirect_stderr, redirect_stdout

    from gyrocal.calib.estimators import fit_full_matrix, matrix_in_frame
    from gyrocal.kit.cli import main as cli
    from gyrocal.kit.pipeline import extract_recording
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.sim import REALISM_EFFECTS

    seed, which = job
    if which == "all":
        flags = ["--sim-realism", "on"]
    elif which == "none":
        flags = ["--sim-realism", "off"]
    elif which.startswith("all but "):
        flags = [x for e in which[len("all but "):].split(" & ") for x in ("--sim-without", e)]
    else:
        flags = [x for e in REALISM_EFFECTS if e != which for x in ("--sim-without", e)]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "run"
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            cli(["calibrate", "--sim", "--sim-seed", str(seed), "--out", str(d), "--quiet",
                 "--no-report", "--protocol", "full", "--sim-cross-axis", "0.02", *flags])
        rec = load_recording(d / "recording")
        t = dict(rec.truth)
        sensing = np.diag(1 / np.asarray(t["scale"])) @ np.asarray(t["misalignment"])
        C = matrix_in_frame(sensing)
        g = (t.get("realism") or {}).get("g-sensitivity", "off")
        Gt = None if g == "off" else np.asarray(g["matrix_rad_s_per_g"])
        if Gt is not None:
            t["_G_model"] = -Gt @ (C @ sensing).T
        obs = extract_recording(rec).observations
        before = _errors(fit_full_matrix(obs, g_sensitivity=False), C, t, Gt)
        after = _errors(fit_full_matrix(obs), C, t, Gt)
    return {"which": which, "before": before, "after": after}


def _rms(xs: list[np.ndarray]) -> float:
    x = np.concatenate(xs) if xs else np.zeros(0)
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def effect_costs(seeds: int, cases: list[str] | None = None) -> None:
    """The per-effect table: every effect alone, none and all (``cases`` to choose), each
    recording fitted without the g-sensitivity term (before) and with it (after)."""
    import os
    from concurrent.futures import ProcessPoolExecutor

    from gyrocal.kit.sim import REALISM_EFFECTS, realism_sizes

    sizes = realism_sizes()
    if cases is None:
        cases = ["none", *REALISM_EFFECTS, "all", "all but wobble"]
    # seed-major, so that a long run stopped early (Ctrl-C) still has every case at nearly the
    # same number of seeds; the table is printed from the runs that finished
    jobs = [(s, c) for s in range(seeds) for c in cases]
    results = []
    pool = ProcessPoolExecutor(min(2, os.cpu_count() or 1))
    try:
        for (seed, case), r in zip(jobs, pool.map(_effect_run, jobs), strict=True):
            results.append(r)  # one line per run as it lands, for a long table's progress
            zb, za = _rms([r["before"]["bias_z"]]), _rms([r["after"]["bias_z"]])
            print(f"# {case} seed {seed}: χ² ok {r['before']['ok']}→{r['after']['ok']}, bias "
                  f"err/σ RMS {zb:.2f}→{za:.2f}", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        print(f"# stopped after {len(results)} of {len(jobs)} runs; the table below holds "
              "those", file=sys.stderr, flush=True)
        pool.shutdown(wait=False, cancel_futures=True)
    else:
        pool.shutdown()
    rows = []
    for c in cases:
        rs = [r for r in results if r["which"] == c]
        if not rs:
            continue
        row: list = [c, sizes.get(c, "")]
        cols = {}
        for when in ("before", "after"):
            e = [r[when] for r in rs]
            cols[when] = [_rms([x[k] for x in e]) for k in ("scale", "cross", "bias")]
            cols[when] += [_rms([x["bias_z"] for x in e]), sum(x["ok"] for x in e)]
        b, a = cols["before"], cols["after"]
        row += [a[0], a[0] / b[0], a[1], a[1] / b[1], a[2], a[2] / b[2], b[3], a[3],
                f"{b[4]}/{len(rs)}", f"{a[4]}/{len(rs)}",
                _rms([r["after"]["g_z"] for r in rs])]
        rows.append(row)
    print_table(["effect", "size", "scale RMS", "÷before", "cross RMS", "÷before",
                 "bias RMS rad/s", "÷before", "bias err/σ before", "after", "χ² ok before",
                 "after", "G err/σ RMS"], rows,
                title=f"Cost of each realism effect (emulated MPU-9250, protocol full, ±2 % "
                      f"cross-axis, {len(results)} runs of seeds 0..{seeds - 1}); after = "
                      "with g-sensitivity in the model (the default), before = the same "
                      "recordings without it")


def independent_g(seeds: int) -> None:
    """g-sensitivity on Recording v1 from the independent generator
    (tests/kit/contract_fullmodel_recording.py: scipy rotations, servo 3 vertical at home, a
    gravity rest; no gyrocal code): G drawn within the MPU-9250's ±0.1 °/s/g per term; the
    fit's G and zero-g bias errors in their σ, and χ², with and without the term."""
    import tempfile

    from gyrocal.calib.estimators import fit_full_matrix, matrix_in_frame
    from gyrocal.kit.pipeline import extract_recording
    from gyrocal.kit.recording import load_recording
    from tests.kit.contract_fullmodel_recording import write_recording

    gz, bz_before, bz_after, ok_before, ok_after, err_g = [], [], [], 0, 0, []
    for seed in range(seeds):
        G = np.random.default_rng([seed, 0x65]).uniform(-1.0, 1.0, (3, 3)) * math.radians(0.1)
        with tempfile.TemporaryDirectory() as tmp:
            truth = write_recording(Path(tmp) / "rec", seed=seed, g_sensitivity=G)
            obs = extract_recording(load_recording(Path(tmp) / "rec")).observations
        sensing = np.diag(1 / truth["scale"]) @ truth["misalignment"]
        Q = matrix_in_frame(sensing) @ sensing
        before, after = fit_full_matrix(obs, g_sensitivity=False), fit_full_matrix(obs)
        g_std = np.sqrt(np.diag(after.g_sensitivity_cov)).reshape(3, 3)
        dG = after.g_sensitivity + G @ Q.T
        gz.append((dG / g_std).ravel())
        err_g.append(dG.ravel())
        bz_before.append((before.bias - truth["bias"]) / before.bias_std)
        bz_after.append((after.bias - truth["bias"]) / after.bias_std)
        ok_before += before.consistency.ok
        ok_after += after.consistency.ok
    print_table(["seeds", "G err RMS rad/s/g", "G err/σ RMS", "max |G err|/σ",
                 "bias err/σ RMS before", "after", "χ² ok before", "after"],
                [[seeds, _rms(err_g), _rms(gz), float(np.max(np.abs(np.concatenate(gz)))),
                  _rms(bz_before), _rms(bz_after), f"{ok_before}/{seeds}",
                  f"{ok_after}/{seeds}"]],
                title="g-sensitivity on the independent generator's recordings (G within "
                      "±0.1 °/s/g per term)")


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    seeds = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("--seeds=")),
                 3 if quick else 30)
    if "--independent" in argv:
        independent_g(seeds)
        return
    if "--effects-only" not in argv:
        bus_timing(300 if quick else 3000)
        lsm_bandwidth()
        clients()
    cases = next((a.split("=", 1)[1].split(",") for a in argv if a.startswith("--cases=")),
                 None)
    effect_costs(seeds, cases)
