"""The full model g = A (m + b) (issue 10): accuracy in general motion, honest uncertainty.

1. Emulated MPU-9250s with ±2 % cross-axis (``gyrocal calibrate --sim`` at its defaults: the
   full protocol, the datasheet's cross-axis terms) against the paper's protocol with Algorithm 1
   on the same sensors: RMS general-motion rate error per rad/s
   (:func:`gyrocal.calib.design.general_motion_rms`), jig time, χ² verdicts, the 12 parameters'
   errors in their own σ; and the time ``gyrocal verify``'s general-motion sweeps add, counted
   apart from the calibration's jig time.
2. Monte Carlo (vectorised, window level) on the windows, poses and noise of one emulated default
   run: coverage of each of the 12 parameters' 95 % intervals, the χ² test's false-alarm rate
   against its 1 % level, and the error variance against the Cramér–Rao bound (the inverse
   Fisher information at the truth, which is the estimator's own covariance there).
3. The same on the independent generator of tests/calib/fullmodel_truth.py (scipy rotations, no
   gyrocal kinematics), with its own pose schedule (90° poses).
4. Efficiency against a Cramér–Rao bound derived apart from the estimator (the independent
   generator's own finite-difference Fisher information), with score_full_design's σ.
5. ``gyrocal estimate`` on sample-level Recording v1 directories of the independent generator
   tests/kit/contract_fullmodel_recording.py (60° poses, a two-servo pose move): errors in σ, χ²
   false alarms, general-motion error of the full model against the diagonal ones.

6. The model choice (issue 28): general-motion error and consistency-verdict rate of ``gyrocal
   estimate``'s method ``auto`` (the full model kept when its predicted general-motion error is
   below the diagonal model's) on normal and the paper's extreme sensors (scale 1.2–2.0, |bias|
   0.1–0.2 rad/s), full (posed) and diagonal (home turns only) protocols, on the emulator
   (``gyrocal calibrate --sim``, ``--sim-sensor paper-extreme``; :data:`EMULATED_PROTOCOLS`) and
   on the independent generator (tests/kit/contract_fullmodel_recording.py, ``extreme=True``;
   :data:`CHOICE_PROTOCOLS`), on held-out seeds from :data:`CHOICE_SEEDS` (none of them looked
   at while writing the code).

Usage: ``python -m bench fullmodel [--quick] [--seeds=N] [--jig-only] [--independent-default]
[--model-choice [--no-emulator]]``:
``--seeds`` sensors in the jig table (default 12; 3 with ``--quick``), ``--jig-only`` the jig
table and the verify sweep time alone, ``--independent-default`` only the default plan's schedule
(accelerometer rests included) on ``--seeds`` independent recordings, ``--model-choice`` only
section 6 (``--seeds`` sensors per row, default 12 independent and 3 emulated;
``--no-emulator`` the independent rows alone). The jig table runs seed
by seed (a line per sensor as it lands, on stderr); Ctrl-C
prints the table of the sensors that finished.
"""

from __future__ import annotations

import io
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np
from scipy import stats

from bench.table import pooled, print_table

NAMES = [f"A_{r}{c}" for r in "xyz" for c in "xyz"] + ["b_x", "b_y", "b_z"]

#: The Monte Carlo sections draw their own truths on the windows of a run of the model's own
#: sensor (no realism effects: white noise, so the window-level noise model is exact).
SIM = ["--sim", "--sim-realism", "off"]

#: The jig table's sensor: ``gyrocal calibrate --sim`` at its defaults, every realism effect of
#: issue 12 on (coloured noise, DLPF, g-sensitivity, gravity, wobble, clock, encoder latency).
SIM_DEFAULT = ["--sim"]


def _run(seed: int) -> dict:
    """One sensor: the default protocol (full model) and the paper's protocol (Algorithm 1), the
    default realistic emulated sensor (:data:`SIM_DEFAULT`). The general-motion error is the
    calibration's ``A`` and zero-g ``b`` against the truth's (:func:`general_motion_rms`); the
    paper's bias, fitted in the home pose, carries g-sensitivity's home shift as an error.
    """
    from gyrocal.calib.design import general_motion_rms, predicted_general_motion_rms
    from gyrocal.calib.estimators import estimate, matrix_in_frame
    from gyrocal.kit.cli import main
    from gyrocal.kit.pipeline import estimate_recording, extract_recording
    from gyrocal.kit.recording import load_recording

    out: dict = {"seed": seed}
    for protocol in ("full", "paper"):
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp) / "run"
            t0 = time.perf_counter()
            flags = [] if protocol == "full" else ["--protocol", protocol]  # full: the default
            with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
                main(["calibrate", *SIM_DEFAULT, "--sim-seed", str(seed), "--out", str(d),
                      "--quiet", "--no-report", *flags])
            rec = load_recording(d / "recording")
            t = rec.truth
            C = np.diag(1 / np.asarray(t["scale"])) @ np.asarray(t["misalignment"])
            b = np.asarray(t["bias"])
            jig = float(rec.imu_t[-1] - rec.imu_t[0])
            if protocol == "full":
                fit = estimate_recording(rec).fit
                std = np.sqrt(np.diag(fit.covariance))
                err = np.concatenate([(fit.matrix - matrix_in_frame(C)).ravel(), fit.bias - b])
                out.update(
                    method=fit.method, jig_s=jig, wall_s=time.perf_counter() - t0,
                    gm=general_motion_rms(fit.matrix, fit.bias, C, b),
                    gm_pred=predicted_general_motion_rms(fit.covariance),
                    z=np.where(std > 0, err / np.where(std > 0, std, 1), 0.0).tolist(),
                    ok=bool(fit.consistency.ok))
            else:
                ils = estimate(extract_recording(rec).observations, "iterative-ls")
                out.update(paper_jig_s=jig,
                           gm_paper=general_motion_rms(np.diag(ils.scale), ils.bias, C, b))
    return out


def jig_table(seeds: list[int]) -> list[dict]:
    """The jig table, seed by seed (two sensors at once); Ctrl-C prints the sensors that
    finished."""
    rs = pooled(_run, seeds, lambda r: f"seed {r['seed']}: full {r['gm']:.2e} per rad/s in "
                f"{r['jig_s']:.1f} s (χ² ok {r['ok']}), paper {r['gm_paper']:.2e} in "
                f"{r['paper_jig_s']:.1f} s")
    if not rs:
        return rs
    gm = np.array([r["gm"] for r in rs])
    gp = np.array([r["gm_paper"] for r in rs])
    rms = float(np.sqrt(np.mean(gm**2)))
    rms_p = float(np.sqrt(np.mean(gp**2)))
    jig = np.array([r["jig_s"] for r in rs])
    done = [r["seed"] for r in rs]
    print_table(
        ["protocol / estimator", "sensors", "general-motion RMS err per rad/s", "worst",
         "jig time s (mean)", "jig time s (max)"],
        [["full (posed) / full-matrix", len(rs), rms, float(gm.max()), float(jig.mean()),
          float(jig.max())],
         ["paper's protocol / Algorithm 1", len(rs), rms_p, float(gp.max()),
          float(np.mean([r["paper_jig_s"] for r in rs])),
          float(np.max([r["paper_jig_s"] for r in rs]))],
         ["ratio full / paper", "", rms / rms_p, "", "", ""]],
        title="Emulated MPU-9250s, the default realistic sensor with ±2 % cross-axis (gyrocal "
              f"calibrate --sim, seeds {', '.join(map(str, done))}); targets: <= 5e-4, "
              "<= 0.05x paper, jig <= 45 s")
    z = np.array([r["z"] for r in rs])
    print_table(
        ["fits", "method full-matrix", "chi2 consistent", "RMS err/σ (9 free + 3 bias)",
         "max |err/σ|", "predicted general-motion RMS (mean)"],
        [[len(rs), sum(r["method"] == "full-matrix" for r in rs), sum(r["ok"] for r in rs),
          float(np.sqrt(np.mean(z[:, np.any(z != 0, axis=0)] ** 2))), float(np.abs(z).max()),
          float(np.mean([r["gm_pred"] for r in rs]))]],
        title="The same fits against the emulator's truth, in their own σ")
    print(f"wall time of gyrocal calibrate --sim --no-report (default), two runs at once: median "
          f"{np.median([r['wall_s'] for r in rs]):.1f} s, max "
          f"{np.max([r['wall_s'] for r in rs]):.1f} s\n")
    return rs


def verify_sweep_time(seed: int = 0) -> None:
    """Jig time of ``gyrocal verify --sim``: the protocol and, apart, the general-motion sweeps
    (the segments after the protocol's last one)."""
    from gyrocal.kit.cli import main
    from gyrocal.kit.recording import load_recording

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            main(["calibrate", *SIM_DEFAULT, "--sim-seed", str(seed), "--out", str(d / "cal"),
                  "--quiet", "--no-report"])
            main(["verify", str(d / "cal" / "calibration.json"), *SIM_DEFAULT, "--sim-seed",
                  str(seed), "--out", str(d / "verify"), "--quiet"])
        cal = load_recording(d / "cal" / "recording")
        ver = load_recording(d / "verify" / "recording")
    protocol_s = max(s.t_end for s in cal.segments) - min(s.t_start for s in cal.segments)
    n = len(cal.segments)
    start = ver.segments[n - 1].t_end if len(ver.segments) > n else None
    sweeps = max(s.t_end for s in ver.segments) - start if start is not None else float("nan")
    print_table(["", "jig time s"],
                [["calibration protocol (default)", float(protocol_s)],
                 ["verify: the protocol again", float(start - ver.segments[0].t_start)],
                 ["verify: general-motion sweeps (with their rests)", float(sweeps)]],
                title=f"Jig time of gyrocal verify --sim (seed {seed}), the sweeps counted apart")


def _mc(name: str, fit_inputs, truth_A: np.ndarray, truth_b: np.ndarray) -> None:
    from gyrocal.calib.estimators import full_matrix_batch

    t0 = time.perf_counter()
    res = full_matrix_batch(**fit_inputs)
    wall = time.perf_counter() - t0
    B = truth_A.shape[0]
    err = np.concatenate([(res.matrix - truth_A).reshape(B, 9), res.bias - truth_b], axis=1)
    std = np.sqrt(np.clip(np.diagonal(res.covariance, axis1=1, axis2=2), 0, None))
    free = np.all(std > 0, axis=0)
    cover = np.mean(np.abs(err) <= 1.96 * np.where(std > 0, std, np.inf), axis=0)
    crb = np.mean(std**2, axis=0)
    var = err.var(axis=0)
    rows = [[NAMES[j], float(cover[j]), float(crb[j] / var[j])] for j in range(12) if free[j]]
    print_table(["parameter", "95 % interval coverage", "CRB / error variance"], rows,
                title=f"{name}: {B} runs, converged {int(res.converged.sum())}, "
                      f"{wall:.1f} s (targets: coverage 0.93-0.97, efficiency >= 0.9)")
    p = stats.chi2.sf(res.chi2, res.dof)
    print(f"chi-square on {res.dof} dof: false-alarm rate at the 1 % level = "
          f"{np.mean(p < 0.01):.4f} (target 0.00-0.02); mean chi2/dof = "
          f"{np.mean(res.chi2) / res.dof:.3f}\n")


def jig_mc(seed: int, B: int) -> None:
    """Window-level Monte Carlo on one emulated default run's windows, poses and noise."""
    from gyrocal.calib.estimators import matrix_in_frame
    from gyrocal.calib.kinematics import chain_axes
    from gyrocal.kit.cli import main
    from gyrocal.kit.pipeline import extract_recording
    from gyrocal.kit.recording import load_recording

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "run"
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            main(["calibrate", *SIM, "--sim-seed", str(seed), "--out", str(d), "--quiet"])
        obs = extract_recording(load_recording(d / "recording")).observations.with_pooled_noise()
    rng = np.random.default_rng(seed)
    n, S = obs.pose.shape
    A_n = obs.n_still_angles
    q = obs.still_angle_std * np.sqrt(12)
    # Truths: ±2 % cross-axis, scales ±3 %, biases ±0.05 rad/s, servo axes tilted by ~1°.
    off = rng.uniform(-0.02, 0.02, (B, 3, 3)) * (1 - np.eye(3))
    C = np.einsum("bi,bij->bij", 1 / rng.uniform(0.97, 1.03, (B, 3)), np.eye(3) + off)
    bias = rng.uniform(-0.05, 0.05, (B, 3))
    axes = np.eye(3)[None] + rng.normal(0, 0.015, (B, 3, 3))
    axes /= np.linalg.norm(axes, axis=2, keepdims=True)
    ref = obs.pose[0]
    z = rng.uniform(-q / 2, q / 2, (B, A_n))  # reading − true of every still angle
    ps = obs.pose_still
    zp = np.where(ps >= 0, z[:, np.where(ps >= 0, ps, 0)], 0.0)
    true_delta = obs.pose - ref - zp
    u = chain_axes(axes[:, None], 0.0, true_delta)[:, np.arange(n), obs.motor_index]
    G = obs.reference_matrix()
    true_rate = obs.rate - z @ G.T + rng.normal(0, 1, (B, n)) * obs.rate_std
    mean = np.einsum("bij,bnj->bni", C, u) * true_rate[..., None] - bias[:, None]
    mean += rng.normal(0, 1, mean.shape) * obs.mean_std
    rest = -bias[:, None] + rng.normal(0, 1, (B,) + obs.rest_mean.shape) * obs.rest_mean_std
    A_true = np.array([matrix_in_frame(c) for c in C])
    inputs = dict(
        mean=mean, rate=np.broadcast_to(obs.rate, (B, n)).copy(), motor_index=obs.motor_index,
        pose=obs.pose, mean_std=np.broadcast_to(obs.mean_std, mean.shape).copy(),
        rate_std=np.broadcast_to(obs.rate_std, (B, n)).copy(), rest_mean=rest,
        rest_std=np.broadcast_to(obs.rest_mean_std, rest.shape).copy(), n_servos=S,
        ref_matrix=G, still_std=obs.still_angle_std, pose_still=ps)
    _mc("Monte Carlo on the emulated default run's windows (sub-tick holds uniform)", inputs,
        A_true, bias)


def independent_mc(B: int) -> None:
    """Runs of the independent generator (tests/calib/fullmodel_truth.py), 90° pose schedule."""
    from gyrocal.calib.estimators import fit_full_matrix
    from tests.calib.fullmodel_truth import POSED, draw_truth, posed_observations, truth_in_frame

    rng = np.random.default_rng(2026)
    errs, stds, chi, dof = [], [], [], 0
    gm = []
    from gyrocal.calib.design import general_motion_rms

    for _ in range(B):
        C, bias, links, mount = draw_truth(rng)
        fit = fit_full_matrix(posed_observations(C, bias, links, mount, POSED, noise=0.03,
                                                 count=1000, rng=rng))
        errs.append(np.concatenate([(fit.matrix - truth_in_frame(C)).ravel(), fit.bias - bias]))
        stds.append(np.sqrt(np.diag(fit.covariance)))
        chi.append(fit.consistency.chi2)
        dof = fit.consistency.dof
        gm.append(general_motion_rms(fit.matrix, fit.bias, C, bias))
    err, std = np.array(errs), np.array(stds)
    free = np.all(std > 0, axis=0)
    cover = np.mean(np.abs(err) <= 1.96 * np.where(std > 0, std, np.inf), axis=0)
    var = err.var(axis=0)
    eff = np.mean(std**2, axis=0) / np.where(var > 0, var, np.inf)  # 0 where the frame fixes it
    print_table(["parameter", "95 % interval coverage", "CRB / error variance"],
                [[NAMES[j], float(cover[j]), float(eff[j])] for j in range(12) if free[j]],
                title=f"Independent generator (scipy rotations, 90° poses, σ = 0.03 rad/s per "
                      f"sample, 1000 samples per window): {B} runs")
    p = stats.chi2.sf(np.array(chi), dof)
    print(f"chi-square on {dof} dof: false-alarm rate at 1 % = {np.mean(p < 0.01):.4f}; "
          f"general-motion RMS error per rad/s = {np.sqrt(np.mean(np.square(gm))):.2e}\n")


def crb_mc(B: int) -> None:
    """Efficiency against an independently derived Cramér–Rao bound: ``B`` noisy runs of the
    independent generator at one truth (A = I, b = 0, link axes tilted ~2°, 90° poses), the
    bound from its own finite-difference Fisher information
    (tests/calib/fullmodel_truth.independent_fisher), next to score_full_design's σ."""
    from gyrocal.calib.design import full_schedule, score_full_design
    from gyrocal.calib.estimators import fit_full_matrix
    from tests.calib.fullmodel_truth import independent_fisher, posed_observations

    rng = np.random.default_rng(77)
    links = np.eye(3) + rng.uniform(-0.03, 0.03, (3, 3))
    links /= np.linalg.norm(links, axis=1, keepdims=True)
    poses = ((1, 2, np.pi / 2), (0, 1, np.pi / 2))
    sched = full_schedule(poses)
    noise, count, rate, rests = 0.03, 1000, 3.0, 3
    sigma = noise / np.sqrt(count)
    crb, _ = independent_fisher(links, sched, rate, sigma, sigma, rests)
    score = score_full_design(sched, rate=rate, window_std=sigma, rest_std=sigma,
                              n_rests=rests, axes=links)
    errs, chi = [], []
    t0 = time.perf_counter()
    for _ in range(B):
        fit = fit_full_matrix(posed_observations(
            np.eye(3), np.zeros(3), list(links), np.eye(3), sched, speed=rate, noise=noise,
            count=count, rests=rests, rng=rng))
        errs.append(np.concatenate([(fit.matrix - np.eye(3)).ravel(), fit.bias]))
        chi.append((fit.consistency.chi2, fit.consistency.dof))
    err = np.array(errs)
    free = crb > 0
    var = err.var(axis=0)
    cover = np.mean(np.abs(err) <= 1.96 * np.where(free, crb, np.inf), axis=0)
    print_table(
        ["parameter", "CRB σ (independent)", "score_full_design σ", "error σ (MC)",
         "CRB / error variance", "95 % coverage of ±1.96 CRB σ"],
        [[NAMES[j], float(crb[j]), float(score.parameter_std[j]), float(np.sqrt(var[j])),
          float(crb[j] ** 2 / var[j]), float(cover[j])] for j in range(12) if free[j]],
        title=f"Efficiency against an independent Cramér–Rao bound: {B} runs of the independent "
              f"generator at one truth (90° poses, σ = {noise} rad/s per sample, {count} samples "
              f"per window), {time.perf_counter() - t0:.0f} s; score_full_design G-efficiency "
              f"{score.g_efficiency:.3f}")
    c2 = np.array(chi)
    p = stats.chi2.sf(c2[:, 0], c2[:, 1])
    print(f"chi-square false-alarm rate at 1 % = {np.mean(p < 0.01):.4f}\n")


def _independent_recording(seed: int) -> dict:
    """One sample-level recording of the independent generator, estimated by gyrocal."""
    from gyrocal.calib.design import general_motion_rms, predicted_general_motion_rms
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording
    from tests.calib.fullmodel_truth import truth_in_frame
    from tests.kit.contract_fullmodel_recording import write_recording

    with tempfile.TemporaryDirectory() as tmp:
        truth = write_recording(Path(tmp) / "rec", seed=seed)
        t0 = time.perf_counter()
        rec = load_recording(Path(tmp) / "rec")
        est = estimate_recording(rec)
        wall = time.perf_counter() - t0
        diag = estimate_recording(rec, "paired-axis").fit
        ils = estimate_recording(rec, "iterative-ls").fit
    fit = est.fit
    C = np.diag(1 / truth["scale"]) @ truth["misalignment"]
    b = truth["bias"]
    std = np.sqrt(np.diag(fit.covariance))
    err = np.concatenate([(fit.matrix - truth_in_frame(C)).ravel(), fit.bias - b])
    return {"seed": seed, "method": fit.method, "p": fit.consistency.p_value,
            "z": np.where(std > 0, err / np.where(std > 0, std, 1), 0.0).tolist(),
            "gm": general_motion_rms(fit.matrix, fit.bias, C, b),
            "gm_pred": predicted_general_motion_rms(fit.covariance),
            "gm_diag": general_motion_rms(np.diag(diag.scale), diag.bias, C, b),
            "gm_ils": general_motion_rms(np.diag(ils.scale), ils.bias, C, b), "wall_s": wall}


def independent_recordings(seeds: list[int]) -> None:
    """`estimate` on sample-level Recording v1 directories of the independent generator
    (tests/kit/contract_fullmodel_recording.py: scipy rotations, a skewed gimbal, 60° poses, a
    pose moving two servos at once, ±2 % cross-axis, MPU-9250 noise and LSB, 4096-tick
    encoders)."""
    rs = pooled(_independent_recording, seeds, lambda r: f"recording {r['seed']}: "
                f"{r['method']}, GM {r['gm']:.2e} per rad/s (predicted {r['gm_pred']:.2e})")
    if not rs:
        return
    z = np.array([r["z"] for r in rs])
    zf = z[:, np.any(z != 0, axis=0)]
    gm = np.array([r["gm"] for r in rs])
    print_table(
        ["recordings", "method full-matrix", "chi2 p < 0.01", "RMS err/σ", "max |err/σ|",
         "|err/σ| < 1.96", "GM RMS full", "GM predicted (mean)", "GM RMS paired-axis",
         "GM RMS Algorithm 1"],
        [[len(rs), sum(r["method"] == "full-matrix" for r in rs),
          sum(r["p"] < 0.01 for r in rs), float(np.sqrt(np.mean(zf**2))),
          float(np.abs(zf).max()), float(np.mean(np.abs(zf) < 1.96)),
          float(np.sqrt(np.mean(gm**2))), float(np.mean([r["gm_pred"] for r in rs])),
          float(np.sqrt(np.mean([r["gm_diag"] ** 2 for r in rs]))),
          float(np.sqrt(np.mean([r["gm_ils"] ** 2 for r in rs])))]],
        title="gyrocal estimate on the independent sample-level generator (seeds "
              f"{rs[0]['seed']}..{rs[-1]['seed']}; GM = general-motion RMS rate error per rad/s)")


def independent_default_plan(seeds: list[int]) -> None:
    """The merged default plan (accelerometer rests included) on independent data: the schedule
    of a default ``gyrocal calibrate --sim`` run's segments.csv (moves to the nearest 45°), laid
    out by the independent generator (tests/kit/contract_fullmodel_recording.py ``steps=``, no
    gyrocal code in its data) with G within ±0.1 °/s/g; the full fit's χ², errors in σ, and its
    general-motion RMS rate error per rad/s (:func:`gyrocal.calib.design.general_motion_rms`,
    against the generator's truth) with the value its covariance predicts."""
    import csv
    import json

    from gyrocal.calib.design import general_motion_rms, predicted_general_motion_rms
    from gyrocal.calib.estimators import fit_full_matrix
    from gyrocal.kit.cli import main as cli
    from gyrocal.kit.pipeline import extract_recording
    from gyrocal.kit.recording import load_recording
    from tests.calib.fullmodel_truth import truth_in_frame
    from tests.kit.contract_fullmodel_recording import write_recording

    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            cli(["calibrate", "--sim", "--sim-seed", "0", "--out", str(run), "--quiet",
                 "--no-report"])
        src = run / "recording"
        chain = [int(m["id"]) for m in
                 json.loads((src / "manifest.json").read_text())["gimbal"]["motors"]]
        segs = list(csv.DictReader((src / "segments.csv").read_text("ascii").splitlines()))
        enc = np.loadtxt(src / "encoder.csv", delimiter=",", skiprows=1)
    steps = _steps_of(segs, enc, chain)
    rows, zs, gms = [], [], []
    for seed in seeds:
        G = np.random.default_rng([seed, 0x65]).uniform(-1, 1, (3, 3)) * np.radians(0.1)
        with tempfile.TemporaryDirectory() as tmp:
            truth = write_recording(Path(tmp) / "rec", seed=seed, g_sensitivity=G, steps=steps)
            obs = extract_recording(load_recording(Path(tmp) / "rec")).observations
        sensing = np.diag(1 / truth["scale"]) @ truth["misalignment"]
        C = truth_in_frame(sensing)
        fit = fit_full_matrix(obs)
        gm = general_motion_rms(fit.matrix, fit.bias, sensing, truth["bias"])
        gms.append(gm)
        std = np.sqrt(np.diag(fit.covariance))
        free = std[:9] > 0
        z = np.r_[(fit.matrix - C).ravel()[free] / std[:9][free],
                  (fit.bias - truth["bias"]) / std[9:12]]
        zs.append(z)
        rows.append([seed, fit.consistency.ok, f"{fit.consistency.chi2:.1f}/{fit.consistency.dof}",
                     float(np.max(np.abs(z))), gm, predicted_general_motion_rms(fit.covariance)])
    allz = np.concatenate(zs)
    rows.append(["all (GM: RMS; predicted: mean)", sum(r[1] for r in rows), "",
                 float(np.max(np.abs(allz))), float(np.sqrt(np.mean(np.square(gms)))),
                 float(np.mean([r[5] for r in rows]))])
    print_table(["seed", "χ² ok", "χ²/dof", "max |err/σ|", "general-motion RMS per rad/s",
                 "predicted"], rows,
                title=f"The merged default plan ({len(steps)} steps, accelerometer rests "
                      f"included) on the independent generator; RMS err/σ "
                      f"{float(np.sqrt(np.mean(allz ** 2))):.2f}")


def _steps_of(segs: list[dict], enc: np.ndarray, chain: list[int]) -> list[tuple]:
    """A recording's segments as the independent generator's ``steps``: rests with their
    durations, turns by chain index, and each group of moves as the pose it ends in."""
    def angle(m: int, t: float) -> float:
        r = enc[enc[:, 1] == m]
        return float(np.interp(t, r[:, 0], r[:, 2]))

    home = np.array([angle(m, 0.0) for m in chain])
    steps: list[tuple] = []
    pose: tuple = (0.0, 0.0, 0.0)
    i = 0
    while i < len(segs):
        s = segs[i]
        if s["kind"] == "rest":
            steps.append(("rest", float(s["t_end"]) - float(s["t_start"])))
        elif s["kind"] == "rotate":
            steps.append(("rotate", chain.index(int(s["motor"])), int(s["direction"])))
        else:
            t_end = float(s["t_end"])
            while i + 1 < len(segs) and segs[i + 1]["kind"] == "move":
                i += 1
                t_end = max(t_end, float(segs[i]["t_end"]))
            q = np.round((np.array([angle(m, t_end) for m in chain]) - home) / (np.pi / 4))
            new = tuple(float(x) for x in q * (np.pi / 4))
            if not np.allclose(new, pose):
                steps.append(("move", new))
                pose = new
        i += 1
    return steps


#: Held-out seeds of the model-choice table (section 6): the tests and the development runs use
#: seeds below 100.
CHOICE_SEEDS = 1000


def _home_steps(rest: float = 0.8) -> list[tuple]:
    """A diagonal protocol for the independent generator: each servo turned both ways in the
    home pose, a rest before every turn and after the last (no poses)."""
    steps: list[tuple] = []
    for s in range(3):
        steps += [("rest", rest), ("rotate", s, 1), ("rest", rest), ("rotate", s, -1)]
    return [*steps, ("rest", rest)]


#: The independent generator's protocols of section 6: its own 60° pose schedule (two turns at
#: 4 rad/s), the default plan's schedule (one turn at 4.3 rad/s, 45° poses, the gravity rest)
#: and the home turns alone; the last two with g-sensitivity within ±0.1 °/s/g.
CHOICE_PROTOCOLS = ("full 60°", "full default", "diagonal")
#: The emulator's: ``gyrocal calibrate --sim``'s default (full), and the diagonal protocols
#: ``--protocol auto`` (planned, no poses) and ``--protocol paper`` (the paper's six turns).
EMULATED_PROTOCOLS = ("full", "auto", "paper")


def _choice_independent(job: tuple[int, bool, str]) -> dict:
    """``gyrocal estimate`` (method auto) on one independent recording."""
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording
    from tests.kit.contract_fullmodel_recording import default_plan_steps, write_recording

    seed, extreme, protocol = job
    G = np.random.default_rng([seed, 0x65]).uniform(-1, 1, (3, 3)) * np.radians(0.1)
    kw: dict = {}
    if protocol == "full default":
        kw = dict(steps=default_plan_steps(), speed=4.3, move_speed=4.3, turns=1,
                  g_sensitivity=G)
    elif protocol == "diagonal":
        kw = dict(steps=_home_steps(), g_sensitivity=G)
    with tempfile.TemporaryDirectory() as tmp:
        write_recording(Path(tmp) / "rec", seed=seed, extreme=extreme, **kw)
        rec = load_recording(Path(tmp) / "rec")
        cal = estimate_recording(rec).calibration
    return _choice_row(seed, extreme, protocol, "independent", cal, rec.truth, None)


def _choice_emulated(job: tuple[int, bool, str]) -> dict:
    """``gyrocal calibrate --sim`` (default realism) on one emulated sensor."""
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.cli import main as cli
    from gyrocal.kit.recording import load_recording

    seed, extreme, protocol = job
    flags = (["--sim-sensor", "paper-extreme"] if extreme else []) + (
        [] if protocol == "full" else ["--protocol", protocol])
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "run"
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            code = cli(["calibrate", "--sim", "--sim-seed", str(seed), "--out", str(d),
                        "--quiet", "--no-report", *flags])
        rec = load_recording(d / "recording")
        path = d / "calibration.json"
        cal = GyroCalibration.from_json(path.read_text()) if path.exists() else None
    return _choice_row(seed, extreme, protocol, "emulator", cal, rec.truth, code)


def _choice_row(seed: int, extreme: bool, protocol: str, data: str, cal, truth,
                code: int | None) -> dict:
    from gyrocal.kit.report import error_against_truth

    row = {"seed": seed, "sensor": "extreme" if extreme else "normal", "protocol": protocol,
           "data": data, "code": code}
    if cal is None:
        return {**row, "model": "none", "gm": float("nan"), "pred": float("nan"), "ok": False}
    mc = cal.model_choice
    pred = (float("nan") if mc is None else mc.full if mc.chosen == "full" else mc.diagonal)
    return {**row, "model": "full" if cal.is_full else "diagonal",
            "gm": error_against_truth(cal, truth).general_motion, "pred": pred,
            "ok": cal.consistency is not None and cal.consistency.ok}


def model_choice_table(n_independent: int, n_emulated: int) -> None:
    """Section 6 (module docstring)."""
    jobs = [(CHOICE_SEEDS + i, extreme, protocol) for extreme in (False, True)
            for protocol in CHOICE_PROTOCOLS for i in range(n_independent)]
    rs = pooled(_choice_independent, jobs, _describe_choice)
    if n_emulated:
        rs += pooled(_choice_emulated, [(CHOICE_SEEDS + i, e, p) for e in (False, True)
                                        for p in EMULATED_PROTOCOLS
                                        for i in range(n_emulated)], _describe_choice)
    rows = []
    for data in ("independent", "emulator"):
        for sensor in ("normal", "extreme"):
            for protocol in (*CHOICE_PROTOCOLS, *EMULATED_PROTOCOLS):
                g = [r for r in rs if (r["data"], r["sensor"], r["protocol"])
                     == (data, sensor, protocol)]
                if not g:
                    continue
                gm = np.array([r["gm"] for r in g])
                rows.append([data, sensor, protocol, len(g),
                             sum(r["model"] == "full" for r in g),
                             float(np.sqrt(np.nanmean(gm**2))), float(np.nanmax(gm)),
                             float(np.nanmean([r["pred"] for r in g])),
                             f"{sum(r['ok'] for r in g)}/{len(g)}",
                             "" if data == "independent" else
                             " ".join(str(r["code"]) for r in g)])
    print_table(["data", "sensor", "protocol", "runs", "full model kept",
                 "GM RMS per rad/s", "GM worst", "predicted (mean)", "verdict ok",
                 "exit codes"], rows,
                title="Model choice by predicted general-motion error (gyrocal estimate, method "
                      f"auto), ±2 % cross-axis; held-out seeds from {CHOICE_SEEDS}; targets on "
                      "the full protocol: GM <= 5e-4 normal, <= 1e-3 extreme")


def _describe_choice(r: dict) -> str:
    return (f"{r['data']} {r['sensor']} {r['protocol']} seed {r['seed']}: {r['model']}, GM "
            f"{r['gm']:.2e} (predicted {r['pred']:.2e}), verdict ok {r['ok']}"
            + ("" if r["code"] is None else f", exit {r['code']}"))


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    n = next((a.split("=", 1)[1] for a in argv if a.startswith("--seeds=")), None)
    if n is not None and not (n.isdigit() and int(n) > 0):
        raise SystemExit(f"--seeds needs a positive whole number of sensors, got {n!r}")
    seeds = list(range(int(n) if n is not None else 3 if quick else 12))
    if "--model-choice" in argv:
        model_choice_table(int(n) if n is not None else 12,
                           0 if "--no-emulator" in argv else int(n) if n is not None else 3)
        return
    if "--independent-default" in argv:
        independent_default_plan(seeds)
        return
    jig_table(seeds)
    verify_sweep_time(seeds[0] if seeds else 0)
    if "--jig-only" in argv:
        return
    independent_recordings(list(range(6 if quick else 20)))
    jig_mc(0, 300 if quick else 1000)
    independent_mc(200 if quick else 1000)
    crb_mc(200 if quick else 1000)
