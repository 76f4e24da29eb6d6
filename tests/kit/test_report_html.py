"""`gyrocal report` writes one self-contained HTML page; a real headless Chromium renders it."""

import json
import re

import pytest

from gyrocal.kit.cli import main
from tests.kit.browser import needs_chromium, render


@pytest.fixture(scope="module")
def report(paper_diagonal_report, paper_diagonal_run):
    """The page of ``gyrocal report`` of the shared seeded diagonal run with its calibration and
    a failing verification document (tests/kit/conftest.py ``paper_diagonal_report``), and the
    recording it was drawn from."""
    plots, _ = paper_diagonal_report
    return plots / "report.html", paper_diagonal_run[0] / "recording"


def test_the_page_is_self_contained_and_holds_the_results(report):
    page, _ = report
    text = page.read_text(encoding="utf-8")
    assert not re.search(r"""(src|href)=['"](?!data:)""", text)  # nothing outside the file
    assert text.count("data:image/png;base64,") == len(list(page.parent.glob("*.png"))) > 3
    assert "id=result" in text and "id=verdict" in text and "id=axes" in text
    assert "gyrocal" in text and "chip" in text and "servo 1" in text  # environment


def test_the_verification_verdict_is_said_in_words_with_its_units(report):
    page, _ = report
    text = page.read_text(encoding="utf-8")
    # the document's y axis is 0.02 / 0.005 = 4 times its prediction: over the limit of 3
    verdict = re.search(r"<p id=verification-verdict>(.*?)</p>", text).group(1)
    assert "FAILED" in verdict and "axis y: error 0.02 rad/s is 4.0 times" in verdict
    assert "FAILED" in re.search(r"<section id=summary>.*?</section>", text, re.S).group(0)
    table = re.search(r"<table id=verification>.*?</table>", text).group(0)
    assert "<td class=n>0.20000</td>" in table and "n/a" in table  # before y; no full column
    assert "rad/s" in text[text.index("id=verification-verdict"):text.index("id=verification>")]


def test_a_document_that_is_not_a_verification_is_refused_before_drawing(report, tmp_path,
                                                                         capsys):
    _, rec = report
    bad = tmp_path / "v.json"
    bad.write_text(json.dumps({"rms_before": [0.1, 0.2, 0.3], "blocks": 12}))
    out = tmp_path / "out"
    assert main(["report", str(rec), "--out", str(out),
                 "--verification", str(bad)]) == 2
    assert "not a `gyrocal verify --json` document" in capsys.readouterr().err
    assert not out.exists()


def test_user_strings_are_escaped(tmp_path):
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.report_html import environment, render_html

    cal = GyroCalibration(scale=(1, 1, 1), bias=(0, 0, 0), method="<b>m</b>",
                          axes={"7": {"axis": [1, 0, 0], "nearest": "<x>",
                                        "misalignment_deg": 0.1, "std_deg": 0.01}})
    env = environment({"sensor": {"model": "<script>", "note": {"a": "<s>"}}})
    page = render_html(cal, title="<t>", env=env, calibration="a&b.json")
    for raw in ("<b>m</b>", "<x>", "<script>", "<s>", "<t>", "a&b.json"):
        assert raw not in page, raw
    assert "&lt;script&gt;" in page and "a&amp;b.json" in page


def test_the_existing_page_is_not_replaced_without_force(report, capsys):
    page, rec = report
    assert main(["report", str(rec), "--out", str(page.parent)]) == 2
    assert "report.html already exists" in capsys.readouterr().err


@needs_chromium
def test_a_headless_browser_renders_the_tables_and_decodes_every_plot(report, tmp_path):
    page, _ = report
    dom, height, decoded, images = render(page, tmp_path)
    n = len(list(page.parent.glob("*.png")))
    assert decoded == images == n  # the folded turn plots too
    result = re.search(r'<table id="result">.*?</table>', dom, re.S).group(0)
    assert result.count("<tr>") == 4  # header and x, y, z
    assert "not calibrated" in re.search(r'<section id="summary">.*?</section>', dom,
                                         re.S).group(0)  # a diagonal model's cross-axis terms


def test_calibrate_writes_the_page_when_the_plot_extra_is_installed(tmp_path, capsys, full_run,
                                                                     full_run_stdout):
    pytest.importorskip("matplotlib")
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "report.html").write_text("mine")
    # a directory holding a page (or anything) is refused as a whole before the jig runs
    assert main(["calibrate", "--sim", "--quiet", "--out", str(taken)]) == 2
    assert "already exists; pass --force to replace the run" in capsys.readouterr().err
    assert [p.name for p in taken.iterdir()] == ["report.html"]
    # the shared `gyrocal calibrate --sim` run (tests/kit/conftest.py), which writes its report
    out, code = full_run
    assert code == 0
    assert "and the report" in full_run_stdout
    text = (out / "report.html").read_text(encoding="utf-8")
    assert "id=result" in text and text.count("data:image/png;base64,") > 3
