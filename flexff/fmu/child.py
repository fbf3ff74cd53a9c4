"""run_in_child: a function that calls into an FMU, run in a child process of its own, so that
an FMU that crashes or hangs cannot take the caller with it.

The child is forked from the fork server (fmu.forkserver): it starts in milliseconds yet
inherits none of the caller's FMUs or threads. The FMI call under way is kept in shared
memory, so a child that dies is reported as, e.g., "fmi2DeSerializeFMUstate ... SIGSEGV";
findings sent before a crash (`emit`) are kept, and the child's files are removed whatever the
end. What the child sends is JSON of a bounded length, never unpickled: an FMU that writes to
the pipe cannot run code in the caller. The child dies with the caller (fmu.orphans). A child
that confines itself (fmu.validation's checks, in cosim's sandbox) leaves the sandbox's line in
its folder's REPORT file (`report_path`), which the caller reads (`ChildEnd.report`). A script
that calls this keeps its top level under `if __name__ == "__main__":`.

Docs: "Isolate an FMU" (docs/how-to/isolate-fmu.md).
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import shutil
import signal
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from flexff.fmu.forkserver import Caller, context
from flexff.fmu.printable import printable

_LABEL_BYTES = 256  # room for the name of the call under way
MESSAGE_LIMIT = 1 << 20  # bytes one message from the child may have
REPORT = "sandbox-report.txt"  # in the child's folder: the line of the sandbox that stopped it
REPORT_CHARS = 600  # the most of it read back
# a fresh child's environment as it starts: numpy's BLAS, imported before the child runs,
# starts no threads (the caller's environment is taken over afterwards, Caller.adopt)
ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
_current: Any = None  # the shared label, set in a child process only


@dataclass(frozen=True)
class ChildEnd:
    """How a child ended: what it sent, and, unless it returned, why not."""

    messages: list[Any] = field(default_factory=list)  # what it emitted, in order
    returned: bool = False  # the function returned (an exception it raised is in `error`)
    error: str | None = None  # the exception the function raised, as text
    signal: str | None = None  # the signal that ended it ("SIGSEGV"), if one did
    exit_code: int | None = None  # its exit status, when it exited without returning
    timed_out: bool = False  # still running at the deadline: killed
    call: str = ""  # the FMI call (or step) under way when it ended, "" if none
    report: str = ""  # the line of the sandbox that stopped it, "" if none

    def failure(self, timeout: float) -> str | None:
        """The end as a sentence naming the call under way, None if the function returned."""
        where = f"{self.call}: " if self.call else ""
        if self.timed_out:
            return f"{where}the FMU did not return within {timeout:g} s (timeout)"
        if self.report and not self.returned:
            return f"{where}the sandbox stopped the FMU's process: {self.report}"
        if self.signal is not None:
            return f"{where}the FMU crashed ({self.signal})"
        if not self.returned:
            return f"{where}the FMU ended the process (exit code {self.exit_code})"
        if self.error is not None:
            return f"{where}{self.error}"
        return None


def under_way(what: str) -> None:
    """Name the step now under way in a child (no effect in any other process)."""
    if _current is not None:
        _current.value = what.encode("utf-8", "replace")[:_LABEL_BYTES - 1]


def report_path() -> Path:
    """In a child, the file its sandbox's line goes to (REPORT, in the child's folder)."""
    return Path(tempfile.gettempdir(), REPORT)


def _report(folder: str) -> str:
    """The first line of the child's REPORT, escaped and short ("" if none)."""
    try:
        text = Path(folder, REPORT).read_bytes()[:REPORT_CHARS].decode("utf-8", "replace")
    except OSError:
        return ""
    return printable(text.splitlines()[0] if text.strip() else "")


def _trace_fmi_calls() -> None:
    """Make every FMI call through fmpy name itself as the call under way."""
    from fmpy.fmi1 import _FMU

    call = _FMU._call

    def traced(self: Any, fname: str, *args: Any) -> Any:
        under_way(fname)
        return call(self, fname, *args)

    _FMU._call = traced


def _child(function: Callable[..., Any], args: tuple[Any, ...], sender: Connection,
           label: Any, folder: str, caller: Caller) -> None:
    """The child's whole life: end with the caller, take its environment and folder, trace, run
    `function(emit, *args)`, say how it ended."""
    global _current
    _current = label
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the caller's: it ends the child
    caller.adopt()
    tempfile.tempdir = folder
    _trace_fmi_calls()

    def send(kind: str, message: Any) -> None:
        sender.send_bytes(json.dumps([kind, message]).encode())

    try:
        function(lambda message: send("emit", message), *args)
    except Exception as error:  # the function's own failure, sent as text
        send("raised", str(error) or type(error).__name__)
    else:
        send("returned", None)
    sender.close()


@contextlib.contextmanager
def _environment(values: dict[str, str]) -> Iterator[None]:
    """This process's environment with `values` for the duration (a child started then
    takes them)."""
    before = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for key, value in before.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def _checked(data: bytes) -> tuple[str, Any]:
    """A message from the child: [kind, message] with a kind of the protocol's."""
    kind, message = json.loads(data)
    if kind not in ("emit", "raised", "returned") or (kind == "raised"
                                                      and not isinstance(message, str)):
        raise ValueError(kind)
    return kind, message


def run_in_child(function: Callable[..., Any], args: tuple[Any, ...], timeout: float,
                 fresh: bool = False) -> ChildEnd:
    """Run `function(emit, *args)` in a child process (module doc), `emit(message)` sending a
    message of JSON's types back (tuples come back as lists); kill it after `timeout` seconds.
    `function` must be importable by name. `fresh`: a new interpreter, the caller's own child
    and single-threaded (a sandbox's namespaces need that), instead of the fork server's
    (which waits for the caller's end in a thread); it starts in a second, not milliseconds."""
    starter = (multiprocessing.get_context("spawn") if fresh
               else context(__name__, function.__module__))
    receiver, sender = starter.Pipe(duplex=False)
    label = starter.RawArray("c", _LABEL_BYTES)
    folder = tempfile.mkdtemp(prefix="flexff-child-")
    process = starter.Process(target=_child, daemon=True, args=(
        function, args, sender, label, folder, Caller.now()))
    messages: list[Any] = []
    end: tuple[str, str | None] | None = None
    timed_out = False
    try:
        if fresh:
            with _environment(ONE_THREAD):
                process.start()
        else:
            process.start()
        sender.close()
        deadline = time.monotonic() + timeout
        while end is None:
            left = deadline - time.monotonic()
            if left <= 0 or not receiver.poll(left):  # poll is True at an end of file too
                timed_out = True
                break
            try:
                kind, message = _checked(receiver.recv_bytes(MESSAGE_LIMIT))
            except EOFError:  # the child is gone without saying how it ended
                break
            except (OSError, ValueError, TypeError, RecursionError):  # too long, not the protocol
                end = ("raised", "the FMU's process sent a message that is not the protocol's")
                process.kill()
                break
            if kind == "emit":
                messages.append(message)
            else:
                end = (kind, message)
        if timed_out:
            process.kill()
        process.join()
    finally:
        if process.is_alive():
            process.kill()
            process.join()
        receiver.close()
        report = _report(folder)
        shutil.rmtree(folder, ignore_errors=True)
    code = process.exitcode
    return ChildEnd(
        messages, returned=end is not None, error=end[1] if end and end[0] == "raised" else None,
        signal=signal.Signals(-code).name if code is not None and code < 0 and not timed_out
        else None, exit_code=code, timed_out=timed_out,
        call=label.value.decode("utf-8", "replace") if end is None else "", report=report)
