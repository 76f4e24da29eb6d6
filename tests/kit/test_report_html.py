"""`gyrocal report` writes one self-contained HTML page; a real headless Chromium renders it."""

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from gyrocal.kit.cli import main

CHROMIUM = Path("/usr/bin/chromium")


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    pytest.importorskip("matplotlib")
    d = tmp_path_factory.mktemp("html")
    rec = d / "rec"
    assert main(["simulate-recording", str(rec), "--seed", "5", "--turns", "1"]) == 0
    verification = d / "v.json"
    verification.write_text(json.dumps({"rms_before": [0.1, 0.2, 0.3], "blocks": 12}))
    assert main(["report", str(rec), "--out", str(d / "out"),
                 "--verification", str(verification)]) == 0
    truth = json.loads((rec / "manifest.json").read_text())["truth"]
    return d / "out" / "report.html", truth


def test_the_page_is_self_contained_and_holds_the_results(report):
    page, truth = report
    text = page.read_text(encoding="utf-8")
    assert not re.search(r"""(src|href)=['"](?!data:)""", text)  # nothing outside the file
    assert text.count("data:image/png;base64,") == len(list(page.parent.glob("*.png"))) > 3
    assert "id=result" in text and "id=verdict" in text and "id=axes" in text
    assert "rms_before" in text and "0.1 0.2 0.3" in text
    assert "gyrocal" in text and "chip" in text and "jig" in text  # environment


def test_the_existing_page_is_not_replaced_without_force(report, capsys):
    page, _ = report
    rec = page.parent.parent / "rec"
    assert main(["report", str(rec), "--out", str(page.parent)]) == 2
    assert "report.html already exists" in capsys.readouterr().err


def _chromium(*args, user_data):
    return subprocess.run(
        [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--no-first-run", f"--user-data-dir={user_data}", *args],
        capture_output=True, text=True, timeout=120, check=False,
    )


@pytest.mark.skipif(not CHROMIUM.exists(), reason="no /usr/bin/chromium (Debian: apt-get install "
                                                  "chromium) to render the report in a browser")
def test_a_headless_browser_renders_the_tables_and_decodes_every_plot(report, tmp_path):
    page, truth = report
    # A copy with one script that counts the images the browser decoded (the page has none).
    probe = tmp_path / "probe.html"
    probe.write_text(page.read_text(encoding="utf-8").replace(
        "</body>", "<script>window.onload=()=>{const i=[...document.images];document.title="
        "'decoded '+i.filter(x=>x.complete&&x.naturalWidth>100).length+' of '+i.length;"
        "document.body.dataset.rows=document.querySelectorAll('#result tr').length}</script>"
        "</body>"), encoding="utf-8")
    done = _chromium("--virtual-time-budget=10000", "--dump-dom", probe.as_uri(),
                     user_data=tmp_path / "profile")
    assert done.returncode == 0, done.stderr[-2000:]
    n = len(list(page.parent.glob("*.png")))
    assert f"<title>decoded {n} of {n}</title>" in done.stdout
    assert 'data-rows="4"' in done.stdout  # header and x, y, z
    shot = tmp_path / "shot.png"
    done = _chromium("--window-size=1200,1600", f"--screenshot={shot}", page.as_uri(),
                     user_data=tmp_path / "profile2")
    assert done.returncode == 0 and shot.stat().st_size > 20_000
    shutil.rmtree(tmp_path / "profile", ignore_errors=True)


def test_calibrate_writes_the_page_when_the_plot_extra_is_installed(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "report.html").write_text("mine")
    # a directory holding a page (or anything) is refused as a whole before the jig runs
    assert main(["calibrate", "--sim", "--quiet", "--out", str(taken)]) == 2
    assert "already exists; pass --force to replace the run" in capsys.readouterr().err
    assert [p.name for p in taken.iterdir()] == ["report.html"]
    out = tmp_path / "run"
    # the paper's sensor: with every realism effect on the χ² verdict fails (exit 3)
    assert main(["calibrate", "--sim", "--sim-realism", "off", "--quiet", "--out",
                 str(out)]) == 0
    assert "and the report" in capsys.readouterr().out
    text = (out / "report.html").read_text(encoding="utf-8")
    assert "id=result" in text and text.count("data:image/png;base64,") > 3
