"""Shared test configuration.

Under pytest-xdist (``pytest -n 2``, the README's command) the tests of ``tests/test_docs.py`` run
on one worker, first. They run the documents' commands in reading order in one directory
(:class:`tests.test_docs.DocRunner`), so each test needs every document before its own: split
over two workers, as xdist's default ``load`` scheduling does, both workers ran most of the
documents (several emulated calibrations each). The scheduler below is xdist's
``LoadScopeScheduling`` with every other test a unit of its own, so the rest is balanced as
``load`` balances it; the documents' unit, the largest, is handed out first (xdist orders units
by size). ``--dist`` other than ``load`` is left as asked.
"""

from __future__ import annotations

from typing import Any

import pytest

#: The work unit that keeps the documents' tests together.
DOCS_UNIT = "tests/test_docs.py"

try:
    from xdist.scheduler import LoadScopeScheduling
except ImportError:  # plain pytest: nothing to schedule
    LoadScopeScheduling = None


if LoadScopeScheduling is not None:

    class DocumentsTogether(LoadScopeScheduling):  # type: ignore[misc, valid-type]
        """``load`` scheduling, except that the documents' tests are one unit."""

        def _split_scope(self, nodeid: str) -> str:
            return DOCS_UNIT if nodeid.startswith(DOCS_UNIT + "::") else nodeid

    @pytest.hookimpl(optionalhook=True)
    def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
        """:class:`DocumentsTogether` in place of xdist's ``load`` scheduling."""
        if config.getvalue("dist") == "load":
            return DocumentsTogether(config, log)
        return None
