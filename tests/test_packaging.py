"""The wheel's layout: one import namespace, ``gyrocal``, mapped from the repository's rooms."""

from __future__ import annotations

import importlib
import pathlib
import tomllib

ROOT = pathlib.Path(__file__).resolve().parents[1]
ROOMS = ("kit", "drivers", "calib")


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def test_every_package_folder_is_installed_under_gyrocal():
    listed = set(_pyproject()["tool"]["setuptools"]["packages"])
    on_disk = {
        "gyrocal." + ".".join(init.parent.relative_to(ROOT).parts)
        for room in ROOMS
        for init in (ROOT / room).rglob("__init__.py")
    }
    assert on_disk == listed


def test_rooms_map_to_their_folders():
    mapping = _pyproject()["tool"]["setuptools"]["package-dir"]
    assert mapping == {f"gyrocal.{room}": room for room in ROOMS}


def test_console_script_points_into_the_namespace():
    assert _pyproject()["project"]["scripts"]["gyrocal"] == "gyrocal.kit.cli:main"
    cli = importlib.import_module("gyrocal.kit.cli")
    assert callable(cli.main)


def test_no_source_file_imports_a_bare_room():
    offenders = []
    for room in (*ROOMS, "tests", "bench"):
        for path in (ROOT / room).rglob("*.py"):
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                stripped = line.strip()
                for bare in ROOMS:
                    if stripped.startswith((f"from {bare}.", f"from {bare} ", f"import {bare}")):
                        offenders.append(f"{path.relative_to(ROOT)}:{number}: {stripped}")
    assert offenders == []


# Packages a plain ``pip install .`` must not bring in: plotting is behind the ``plot`` extra,
# documentation and test tools are not the kit's business at run time.
HEAVY = {"matplotlib", "sphinx", "pytest", "numpydoc"}


def _canonical(name: str) -> str:
    return name.lower().replace("_", "-").replace(".", "-")


def test_a_plain_install_brings_in_no_plotting_docs_or_test_tools():
    # Walk the run-time dependency closure from pyproject's `dependencies` through the metadata of
    # the installed distributions (this environment has them all), extras excluded, as pip
    # resolves a plain install. allantools 2024.6 put matplotlib, numpydoc and pytest here.
    from importlib import metadata

    from packaging.requirements import Requirement

    env = {"extra": ""}
    todo = [Requirement(r) for r in _pyproject()["project"]["dependencies"]]
    seen: dict[str, str] = {}
    while todo:
        req = todo.pop()
        name = _canonical(req.name)
        if name in seen or (req.marker is not None and not req.marker.evaluate(env)):
            continue
        seen[name] = str(req)
        try:
            requires = metadata.requires(req.name) or []
        except metadata.PackageNotFoundError:
            continue  # not installed here; its own requirements cannot be walked
        todo.extend(Requirement(r) for r in requires)
    assert HEAVY.isdisjoint(seen), sorted(HEAVY & set(seen))
    # The walk really covered the tree: the core dependencies and theirs are in it.
    assert {"numpy", "scipy", "dynamixel-sdk", "pyserial", "smbus2"} <= set(seen)


def test_plot_extra_is_what_brings_matplotlib():
    extras = _pyproject()["project"]["optional-dependencies"]
    assert any(_canonical(r).startswith("matplotlib") for r in extras["plot"])
