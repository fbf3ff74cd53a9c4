"""fmu.forkserver, the source of clean child processes: an FMU's process (fmu.child) and fresh
workers (cosim.executor's `fresh`, as a machine's trainings use) are not forks of the caller,
yet each has the caller's environment and working folder of the moment it was started, set
after the fork server began, and ends with the caller. A fork of a caller with a thread of its
own would warn on Python 3.12 and later (an error here)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
import warnings

import pytest

from flexff.cosim.executor import execute
from flexff.fmu.child import run_in_child
from flexff.fmu.forkserver import context
from tests.helpers import REPOSITORY, assert_descendants_end_with

SETTING = "FLEXFF_TEST_SETTING"
STATE = "as imported"  # what a process has that imported this module and changed nothing


def _view(_job: object = None) -> tuple[str | None, str, str]:
    """What a child sees: the setting, its folder and STATE."""
    return os.environ.get(SETTING), os.getcwd(), STATE


def _reports(emit) -> None:
    emit(_view())


@pytest.fixture
def busy_caller(monkeypatch, tmp_path):
    """The caller as a master is: a thread of its own running, a setting and a folder changed
    since the fork server started, and a module's state changed in memory only."""
    started = context().Process(target=os.getpid)  # the server started before the changes
    started.start()
    started.join()
    monkeypatch.setenv(SETTING, "set after the server started")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys.modules[__name__], "STATE", "changed in the caller")
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # forking a threaded process
        yield ("set after the server started", str(tmp_path), "as imported")
    stop.set()
    thread.join()


def test_fresh_workers_are_clean_and_take_the_callers_setting_and_folder(busy_caller):
    with execute(_view, [0, 1], workers=2, fresh=True) as running:
        seen = [finished.result for finished in running]
    assert seen == [busy_caller] * 2


def test_an_fmus_process_is_clean_and_takes_the_callers_setting_and_folder(busy_caller):
    end = run_in_child(_reports, (), 30.0)
    assert end.returned and end.error is None
    assert [tuple(message) for message in end.messages] == [busy_caller]


def test_an_fmus_process_ends_with_its_killed_caller(tmp_path):
    """SIGKILL of the caller while its FMU's process hangs: that process ends within seconds,
    though its parent is the fork server (fmu.orphans)."""
    code = ("from tests.fmu.test_forkserver import _hangs; from flexff.fmu.child import "
            "run_in_child; run_in_child(_hangs, (), 600)")
    caller = subprocess.Popen([sys.executable, "-c", code], cwd=REPOSITORY,
                              start_new_session=True)
    assert_descendants_end_with(caller, lambda started: any(  # the FMU's, a server's child
        child.ppid() != caller.pid for child in started))


def _hangs(emit) -> None:
    time.sleep(600)
