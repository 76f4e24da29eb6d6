"""``track --initial-bias-std`` with ``--cal``: the prior of a calibration that has no bias
uncertainty of its own (a thermal fit's document), instead of a refusal the flag could not lift."""

from __future__ import annotations

import json

import numpy as np

from gyrocal.kit.cli import main
from tests.kit.test_export_thermal import make_cal


def test_initial_bias_std_seeds_a_calibration_without_bias_std(tmp_path, capsys):
    cal = make_cal()
    assert all(s is None for s in json.loads(cal.to_json())["bias_std"])
    (tmp_path / "cal.json").write_text(cal.to_json())
    assert main(["simulate-recording", "--seed", "3", str(tmp_path / "rec")]) == 0
    base = ["track", str(tmp_path / "rec"), "--cal", str(tmp_path / "cal.json"), "--causal",
            "--no-tempco", "--json"]
    capsys.readouterr()
    assert main(base) == 2
    err = capsys.readouterr().err
    assert "no usable bias_std" in err and "give --initial-bias-std" in err, err
    stds = {}
    for prior in (0.01, 0.3):
        out = tmp_path / f"t{prior}.json"
        assert main([*base, "--initial-bias-std", str(prior), "--out", str(out)]) == 0
        stds[prior] = np.array(json.loads(out.read_text())["bias_std"])[0]
    # the filter's first estimate starts from the prior given: a wider prior, a wider first std
    assert np.all(stds[0.3] > stds[0.01]), stds
    assert np.all(stds[0.01] <= 0.01 * (1 + 1e-9)), stds
