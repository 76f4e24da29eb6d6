"""Seeded fuzz: damaged recordings and configs give a clear refusal or a right result, never a
traceback, a hang or a silently wrong calibration. (Larger run: ``python -m bench faults``.)"""

from __future__ import annotations

import json
from collections import Counter

import numpy as np

from bench.fuzz_inputs import copy_tree, damage, run_command
from gyrocal.kit.config import load_config, template
from gyrocal.kit.errors import InputError
from tests.kit.contract_recording import write_recording

TRUE_SCALE, TRUE_BIAS = np.array([1.01, 0.99, 1.02]), np.array([0.01, -0.02, 0.005])
FILES = ("imu.csv", "encoder.csv", "segments.csv", "manifest.json")


def judge_estimate(outcome, code, out):
    """Outcome of ``estimate --json`` on a damaged copy of the generator's recording."""
    if outcome != "finished":
        return outcome
    cal = json.loads(out)
    right = (np.allclose(cal["scale"], TRUE_SCALE, atol=0.01)
             and np.allclose(cal["bias"], TRUE_BIAS, atol=0.005))
    return "ok" if right or code == 3 else "silent-wrong"


def test_damaged_recordings(tmp_path):
    good = write_recording(tmp_path / "good", odr=100.0, turns=1)
    rng = np.random.default_rng(17)
    tally, bad = Counter(), []
    for k in range(16):
        d = copy_tree(good, tmp_path / f"r{k}")
        name = FILES[k % len(FILES)]
        how, data = damage((d / name).read_bytes(), rng)
        (d / name).write_bytes(data)
        outcome, code, out, err = run_command(["estimate", str(d), "--json"], timeout_s=30)
        verdict = judge_estimate(outcome, code, out)
        tally[verdict] += 1
        if verdict in ("traceback", "hang", "silent-wrong"):
            bad.append((k, name, how, verdict, err[-300:]))
    assert not bad, bad
    assert tally["refused"] + tally["ok"] == 16


def test_damaged_configs(tmp_path):
    rng = np.random.default_rng(71)
    text = template().encode()
    bad = []
    for k in range(60):
        how, data = damage(text, rng)
        p = tmp_path / f"c{k}.toml"
        p.write_bytes(data)
        try:
            load_config(p)
        except InputError as exc:
            assert len(str(exc)) < 400, str(exc)
        except Exception as exc:
            bad.append((k, how, repr(exc)[:200]))
    assert not bad, bad
