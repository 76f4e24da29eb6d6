"""The suite's work units under pytest-xdist (``tests/conftest.py``): what goes whole to one worker
and the order the units are handed out in."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from tests.conftest import LONG_UNITS, longest_first, work_unit
from tests.test_docs import CHAINS, branch_ids

ROOT = Path(__file__).resolve().parents[1]


def test_a_module_is_one_unit_and_a_chain_of_documents_another():
    assert work_unit("tests/kit/test_calibrate.py::test_doctor_on_the_emulated_jig") == \
        "tests/kit/test_calibrate.py"
    assert work_unit("tests/kit/test_calibrate.py::test_every_subcommand_has_help[track]") == \
        "tests/kit/test_calibrate.py"
    docs = "tests/test_docs.py::test_every_command_in_the_document_works"
    assert work_unit(f"{docs}[hardware_docs/using.md]") == "tests/test_docs.py::running"
    assert work_unit(f"{docs}[README.md]") == "tests/test_docs.py::intro"
    # a test that reads a chain's files goes with the chain; one that runs none with the module
    assert work_unit("tests/test_docs.py::test_recording_v1_fields_match_real_recordings") == \
        "tests/test_docs.py::running"
    assert work_unit("tests/test_docs.py::test_exit_code_table_matches_the_code") == \
        "tests/test_docs.py"
    # a branch of a chain (tests.test_docs.BRANCHES) is a unit of its own
    branch = "tests/test_docs.py::test_every_command_of_a_branch_works[running/thermal]"
    assert work_unit(branch) == "tests/test_docs.py::running/thermal"


def test_the_long_units_go_first_longest_first_and_the_rest_keep_their_order():
    short = ["tests/a.py", "tests/b.py"]
    order = longest_first([short[0], *reversed(LONG_UNITS), short[1]])
    assert order[-2:] == short and sorted(order[:-2]) == sorted(LONG_UNITS)
    seconds = [LONG_UNITS[unit] for unit in order[:-2]]
    assert seconds == sorted(seconds, reverse=True)


def test_every_long_unit_names_a_chain_or_a_module_that_exists():
    for unit in LONG_UNITS:
        module, _, chain = unit.partition("::")
        assert (ROOT / module).is_file(), f"{unit}: no such module"
        assert not chain or chain in CHAINS or chain in branch_ids(), f"{unit}: no such chain"


class _Config:
    """What xdist's scheduler reads of pytest's configuration: two local workers."""

    option = SimpleNamespace(loadscopereorder=True)

    def getvalue(self, name: str) -> Any:
        return {"tx": ["2*popen"], "dist": "load"}[name]


class _Worker:
    """The controller's handle of a worker: records the tests it is sent."""

    def __init__(self, name: str) -> None:
        self.gateway = SimpleNamespace(id=name)
        self.shutting_down = False
        self.sent: list[int] = []

    def send_runtest_some(self, indices: list[int]) -> None:
        self.sent.extend(indices)

    def shutdown(self) -> None:
        self.shutting_down = True


def test_xdist_gets_whole_units_the_longest_first(monkeypatch):
    pytest.importorskip("xdist")
    from tests import conftest

    collection = [
        "tests/kit/test_small.py::test_one",
        "tests/kit/test_long.py::test_one", "tests/kit/test_long.py::test_two",
        "tests/test_docs.py::test_every_command_in_the_document_works[README.md]",
        "tests/test_docs.py::test_every_command_in_the_document_works[hardware_docs/running.md]",
        "tests/test_docs.py::test_recording_v1_fields_match_real_recordings",
        "tests/test_docs.py::test_exit_code_table_matches_the_code",
        "tests/kit/test_many.py::test_one", "tests/kit/test_many.py::test_two",
        "tests/kit/test_many.py::test_three",
    ]
    monkeypatch.setattr(conftest, "LONG_UNITS", {"tests/test_docs.py::running": 200.0,
                                                 "tests/kit/test_long.py": 60.0})
    scheduler = conftest.LongestFirst(_Config())
    workers = [_Worker("gw0"), _Worker("gw1")]
    for w in workers:
        scheduler.add_node(w)
    for w in workers:
        scheduler.add_node_collection(w, collection)
    scheduler.schedule()
    first, second = ([collection[i] for i in w.sent] for w in workers)
    # the longest unit first, whole, on one worker; the next longest on the other
    assert first[:2] == collection[4:6], first
    assert second[:2] == collection[1:3], second
    # run everything: each worker reports its tests done, one at a time, as xdist does
    done = {id(w): 0 for w in workers}
    while any(done[id(w)] < len(w.sent) for w in workers):
        for w in workers:
            if done[id(w)] < len(w.sent):
                scheduler.mark_test_complete(w, w.sent[done[id(w)]])
                done[id(w)] += 1
    ran = [[collection[i] for i in w.sent] for w in workers]
    assert sorted(ran[0] + ran[1]) == sorted(collection)  # every test once
    # a module whole on one worker, and a chain with the test that reads its files
    for together in (collection[7:], collection[1:3], collection[4:6]):
        assert any(set(together) <= set(r) for r in ran), together


def _fixtures_defined() -> set[str]:
    """The names of the functions decorated as pytest fixtures in tests/."""
    import ast

    names = set()
    for path in (ROOT / "tests").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef) and any(
                    "fixture" in ast.unparse(d) for d in node.decorator_list):
                names.add(node.name)
    return names


class _Item:
    """What the marking hook reads of a collected test."""

    def __init__(self, fixtures: list[str]) -> None:
        self.fixturenames = fixtures
        self.markers: list[str] = []

    def add_marker(self, mark: Any) -> None:
        self.markers.append(mark.name)


def test_the_readers_of_an_end_to_end_run_are_marked_long():
    from tests import conftest

    assert conftest.E2E_FIXTURES <= _fixtures_defined()
    reader = _Item(["tmp_path", "full_run", "tmp_path_factory"])
    through = _Item(["runs", "paper_diagonal_run", "run_logs"])  # requested by another fixture
    other = _Item(["tmp_path", "capsys"])
    conftest.pytest_collection_modifyitems([reader, through, other])
    assert reader.markers == ["long"] and through.markers == ["long"] and other.markers == []
