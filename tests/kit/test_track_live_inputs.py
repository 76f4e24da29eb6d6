"""``track --live``: a bad ``--cal`` or ``--noise`` file is exit 2 before the jig is opened (no
servo holds torque, nothing is warmed up for a file that could be read first)."""

from __future__ import annotations

import pytest

import gyrocal.kit.jig
from gyrocal.kit.cli import main


@pytest.mark.parametrize("flag", ["--cal", "--noise"])
def test_a_bad_document_is_refused_before_the_jig_opens(flag, tmp_path, capsys, monkeypatch):
    opened = []

    class Refuse:
        def __init__(self, *args, **kwargs):
            opened.append(args)
            raise AssertionError("the jig was opened")

    monkeypatch.setattr(gyrocal.kit.jig, "Jig", Refuse)
    bad = tmp_path / "doc.json"
    bad.write_text('{"format":')
    code = main(["track", "--live", "--sim", "--duration", "3", flag, str(bad)])
    err = capsys.readouterr().err
    assert code == 2 and f"{flag} {bad} is not valid JSON" in err, err
    assert not opened
