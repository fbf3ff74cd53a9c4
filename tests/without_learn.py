"""A pytest plugin (tests/conftest.py loads it): where the extra "learn" is not installed (no
PyTorch, e.g. CI's Python 3.12 and 3.13), a test module or test that needs it is skipped, with
the reason, instead of failing. Where PyTorch is installed it does nothing, so a test that
imports it by mistake still fails there. A test whose child process or CLI call needs PyTorch
says so with the marker `learn`."""

from __future__ import annotations

import importlib.util
import re
from collections.abc import Generator
from typing import Any

import pytest

from flexff.cli import LEARN  # the extra "learn"'s packages, as the command line names them

INSTALLED = importlib.util.find_spec("torch") is not None
REASON = "needs PyTorch: pip install 'flexff[learn]'"
MISSING = re.compile(r"No module named '(" + "|".join(LEARN) + r")[.']")  # in a collect report


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A test marked `learn` (PyTorch in a child process, or behind the CLI's one line): skipped."""
    if not INSTALLED:
        for item in items:
            if item.get_closest_marker("learn"):
                item.add_marker(pytest.mark.skip(reason=REASON))


def _needs_learn(error: BaseException | None) -> bool:
    """Whether `error` is the import of a package of the extra "learn" that failed."""
    return (isinstance(error, ModuleNotFoundError)
            and (error.name or "").partition(".")[0] in LEARN)


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector: pytest.Collector) -> Generator[None, Any, None]:
    """A test module that imports PyTorch: skipped."""
    outcome = yield
    report = outcome.get_result()
    if not INSTALLED and report.failed and MISSING.search(str(report.longrepr)):
        report.outcome = "skipped"
        report.longrepr = (str(collector.path), 0, f"Skipped: {REASON}")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]
                              ) -> Generator[None, Any, None]:
    """A test (or its fixture) that imports PyTorch: skipped."""
    outcome = yield
    report = outcome.get_result()
    if not INSTALLED and report.failed and _needs_learn(call.excinfo and call.excinfo.value):
        report.outcome = "skipped"
        report.longrepr = (str(item.path), item.location[1] or 0, f"Skipped: {REASON}")
