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
