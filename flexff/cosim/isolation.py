"""An FMU in its own process: a crash or a hang of the FMU ends the run with an error naming the
FMU, the call and the time, instead of taking the master with it (as libcosim's proxyfmu does).

IsolatedInstance stands where an FmuInstance does (cosim.master): the child process (`python -m
flexff.cosim.isolation`, this module's `main`) loads the FMU with the same importer and, unless
told otherwise, inside a sandbox (cosim.sandbox). The engine calls the proxy's functions
(cosim/c/proxy.c), which pass values and commands through shared memory without a system
call while both sides are busy; an isolated FMU gives the same results bit for bit.
Everything else goes over pipes as length-prefixed JSON, bounded in size and checked in shape:
nothing the child sends can run code in the master; its text is escaped (fmu.printable). The
shared memory is sealed at its size (shrunk, the master would die of SIGBUS). The child has no
terminal, stdin from /dev/null, its stdout and stderr in a pipe the master relays
(cosim.child_output). Every call it answers, instantiating included, is bounded by the step
timeout (STEP_TIMEOUT by default). The child dies with its master, however the master ends
(fmu.orphans). Reference: docs/how-to/isolate-fmu.md.
"""

from __future__ import annotations

import ctypes
import fcntl
import functools
import json
import mmap
import os
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from ctypes import c_char, c_char_p, c_double, c_int, c_long, c_longlong, c_size_t, c_void_p
from pathlib import Path
from typing import Any

from flexff.cosim import engine, sandbox
from flexff.cosim.child_output import MessageRelay, OutputRelay, message_writer
from flexff.cosim.sandbox import Sandbox
from flexff.fmu import cache
from flexff.fmu.compile import CFLAGS, compiler_version, run_compiler
from flexff.fmu.errors import RunError
from flexff.fmu.importer import FmuError, FmuInfo, FmuInstance, read_fmu
from flexff.fmu.orphans import die_with
from flexff.fmu.printable import printable

SOURCES = (Path(__file__).parent / "c" / "proxy.c", Path(__file__).parent / "c" / "sandbox.c")
PYTHON, EXIT = ord("P"), ord("X")  # commands proxy_serve hands back (CMD_PYTHON, CMD_EXIT)
SERVE_PYTHON = 1  # proxy_serve's result for a Python request
DIED, TIMED_OUT = 1, 2  # proxy_failure
CLOSE_WAIT = 10.0  # seconds a child has to terminate its FMU and exit after the run
START_WAIT = 60.0  # seconds a child has to start Python (instantiating is a call: the timeout)
STEP_TIMEOUT = 60.0  # seconds each call of an isolated FMU may take, unless the run says
STARTED = "started"  # the child's first answer, before it unpacks and instantiates the FMU
ERROR_CHARS = 4000  # the most of an error message from the child shown
SEALS = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL  # the shared memory's
REQUESTS = ("initialize", "set", "get", "fail", "network_times")  # what the child's Python does
LENGTH = struct.Struct("<Q")  # a message's length prefix
MESSAGE_LIMIT = 64 << 20  # bytes a message may have: a child claiming more is stopped
FOLDER = "flexff-isolated-"  # the prefix of an isolated FMU's folder (its FMU and scratch)
BYTES = "\x00bytes"  # the key of a JSON object that stands for bytes (hexadecimal)


@functools.cache
def library() -> ctypes.CDLL:
    """The compiled proxy, from the cache when its source and the compiler are unchanged."""
    key = cache.digest({**{source.name: source.read_text() for source in SOURCES},
                        engine.HEADER.name: engine.HEADER.read_text(),
                        "cflags": " ".join(CFLAGS), "compiler": compiler_version()})
    path = cache.cached_path(key, ".proxy.so")
    if not path.exists():
        with tempfile.TemporaryDirectory() as tmp:
            built = Path(tmp) / "proxy.so"
            run_compiler(list(SOURCES), built, [engine.HEADER.parent])
            cache.store(key, ".proxy.so", built)
    lib = ctypes.CDLL(str(path))
    lib.proxy_shared_size.argtypes, lib.proxy_shared_size.restype = [c_long], c_size_t
    lib.proxy_open.argtypes = [c_int, c_void_p, c_long, c_double]
    lib.proxy_open.restype = c_void_p
    lib.proxy_post.argtypes, lib.proxy_post.restype = [c_void_p, c_int], None
    lib.proxy_free.argtypes, lib.proxy_free.restype = [c_void_p], None
    lib.proxy_failure.argtypes, lib.proxy_failure.restype = [c_void_p], c_int
    lib.proxy_serve.argtypes = [c_void_p, c_long, c_int, c_void_p, c_void_p, c_void_p,
                                c_void_p]
    lib.proxy_serve.restype = c_int
    lib.sandbox_enter.argtypes = [c_char_p, c_longlong, c_double, c_int, c_longlong, c_long,
                                  c_char_p]
    lib.sandbox_enter.restype = c_int
    return lib


def _functions(instance: FmuInstance) -> list[int]:
    """The set, get and step functions the child serves: the FMU's own, a model-exchange FMU's
    solver step (none before it is initialized, when the engine does not run)."""
    fmi3 = instance.info.fmi_version == "3.0"
    dll = instance.fmu.dll
    functions = [engine.function_address(dll, "fmi3SetFloat64" if fmi3 else "fmi2SetReal"),
                 engine.function_address(dll, "fmi3GetFloat64" if fmi3 else "fmi2GetReal")]
    if instance.stepper is not None:
        return [*functions, instance.stepper.address]
    if instance.model_exchange or instance.scheduled:
        return [*functions, 0]
    return [*functions, engine.function_address(dll, "fmi3DoStep" if fmi3 else "fmi2DoStep")]


def _plain(value: Any) -> Any:
    """What JSON cannot hold as it is: bytes (tagged), numpy's scalars."""
    if isinstance(value, bytes):
        return {BYTES: value.hex()}
    if hasattr(value, "item"):
        return value.item()
    raise TypeError(f"{type(value).__name__} cannot cross to an isolated FMU")


def _encoded(message: Any) -> bytes:
    """A message as JSON, with its length before it."""
    data = json.dumps(message, default=_plain).encode()
    return LENGTH.pack(len(data)) + data


def _decoded(data: bytes) -> Any:
    return json.loads(data, object_hook=lambda o: bytes.fromhex(o[BYTES]) if BYTES in o else o)


def _send(fd: int, message: Any) -> None:
    data = _encoded(message)
    while data:
        data = data[os.write(fd, data):]


class ChildError(RunError):
    """An isolated FMU's process that hung, died or was stopped while it was being started
    (a run's later failures are the master's CosimError): exit 1."""


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


class IsolatedInstance:
    """An FMU instantiated in a child process, with FmuInstance's interface for the master;
    `timeout` (s, None: STEP_TIMEOUT) bounds every call the child answers, instantiating
    included (starting Python: START_WAIT); `confined` (None: not) sandboxes the child; `log`
    (None: none) takes its FMU's log messages as they come (cosim.fmu_log)."""

    _messages: MessageRelay | None = None  # the relay of its log messages, where `log` is given

    def __init__(self, info: FmuInfo, name: str, timeout: float | None = None,
                 solver: str | None = None, confined: Sandbox | None = sandbox.DEFAULT,
                 scheduled: bool = False, log: Callable[[str], None] | None = None) -> None:
        self.info, self.name, self.confined = info, name, confined
        self.timeout = STEP_TIMEOUT if timeout is None else timeout
        self.library = info.path
        self.initialized = False
        self.held: list[str] = []  # the sandbox's layers that hold in the child
        lib = library()
        self._capacity = max(1, len(info.variables))
        self._memory = os.memfd_create(f"flexff-{name}", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
        os.ftruncate(self._memory, lib.proxy_shared_size(self._capacity))
        fcntl.fcntl(self._memory, fcntl.F_ADD_SEALS, SEALS)
        self._shared = mmap.mmap(self._memory, lib.proxy_shared_size(self._capacity))
        self._view = c_char.from_buffer(self._shared)
        self.scratch = Path(tempfile.mkdtemp(prefix=FOLDER))  # the FMU, and its work folder
        (self.scratch / "work").mkdir()
        cmd_read, self._cmd = os.pipe()
        self._ack, ack_write = os.pipe()
        self._report, report_write = os.pipe()
        root = str(Path(sys.modules["flexff"].__file__ or ".").resolve().parent.parent)
        python_path = os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH")])])
        env = ({**os.environ, "PYTHONPATH": python_path} if confined is None
               else sandbox.environment(self.scratch / "work", python_path))
        messages, messages_write = os.pipe() if log is not None else (-1, -1)
        options = {"solver": solver, "scheduled": scheduled, "messages": messages_write,
                   "limits": None if confined is None else sandbox.as_list(confined)}
        output, output_write = os.pipe()
        passed = (cmd_read, ack_write, self._memory, report_write)
        self._process = subprocess.Popen(
            [sys.executable, "-m", "flexff.cosim.isolation", str(info.path), name,
             str(cmd_read), str(ack_write), str(self._memory), str(self._capacity),
             str(os.getpid()), str(self.scratch), str(report_write), json.dumps(options)],
            pass_fds=passed if log is None else (*passed, messages_write), env=env,
            cwd=self.scratch / "work", stdin=subprocess.DEVNULL, stdout=output_write,
            stderr=output_write, start_new_session=True)
        for fd in (cmd_read, ack_write, report_write, output_write, messages_write):
            if fd >= 0:
                os.close(fd)
        self._output = OutputRelay(output, name)
        if log is not None:
            self._messages = MessageRelay(messages, name, log)
        self._proxy = lib.proxy_open(self._ack, ctypes.addressof(self._view), self._capacity,
                                     self.timeout)
        self._timed_out = False
        self._broken = False  # the child hung, died, was stopped or broke the protocol
        try:
            if self._response("starting its process", START_WAIT) != STARTED:
                raise self._refused("starting its process", "an answer that is not the start")
            held = self._response("instantiating it")
            if not (isinstance(held, list) and all(isinstance(h, str) for h in held)):
                raise self._refused("instantiating it", "an answer that is no list of layers")
            self.held = held
        except FmuError as error:
            self.close()
            if not self._broken:  # the FMU's own refusal: an FmuError, as in-process
                raise
            raise ChildError(str(error)) from None
        except BaseException:
            self.close()
            raise

    # -- the engine's calls -------------------------------------------------------------
    def calls(self) -> tuple[bool, int, int, int, int]:
        """(fmi3, component, set, get, step) for the engine's plan: the proxy's functions, with
        FMI 2.0 signatures, and the proxy as the component."""
        lib = library()
        return (False, self._proxy, engine.function_address(lib, "proxy_set"),
                engine.function_address(lib, "proxy_get"),
                engine.function_address(lib, "proxy_step"))

    # -- FmuInstance's interface, answered by the child -------------------------------------
    def initialize(self, values: Mapping[str, Any] | None = None, start_time: float = 0.0,
                   stop_time: float | None = None, tolerance: float | None = None) -> None:
        self._request("initialize", dict(values or {}), start_time, stop_time, tolerance)
        self.initialized = True

    def set(self, values: Mapping[str, Any]) -> None:
        self._request("set", dict(values))

    def get(self, names: Sequence[str]) -> list[Any]:
        result = self._request("get", list(names))
        if not (isinstance(result, list) and len(result) == len(names)):
            raise self._refused("get", f"an answer that is no list of {len(names)} values")
        return result

    def network_times(self) -> dict[str, float] | None:
        if self._gone():
            return None
        times = self._request("network_times")
        if times is not None and not (isinstance(times, dict) and all(
                isinstance(v, (int, float)) for v in times.values())):
            raise self._refused("network_times", "an answer that is no table of times")
        return times

    def network_task(self) -> tuple[int, int] | None:
        """None: a network task's overrun counter lives in the child's memory, which the
        engine cannot read (the child's network_times still report its calls)."""
        return None

    def fail(self, what: str) -> FmuError:
        """The error for a failed call: the sandbox's report, the child's signal, the
        timeout, or the FMU's messages."""
        if self._timed_out or library().proxy_failure(self._proxy) == TIMED_OUT:
            return self._hung(what, self.timeout)
        if self._gone():
            self._broken = True
            code = self._process.wait(CLOSE_WAIT)
            stopped = sandbox.report(self._report) if code == sandbox.STOPPED else ""
            if stopped:
                return FmuError(f"{self.name}: {what} failed: the sandbox stopped its process: "
                                f"{stopped}")
            if code == -signal.SIGXCPU and self.confined is not None:
                return FmuError(f"{self.name}: {what} failed: its process used up its CPU time "
                                f"({self.confined.cpu_s:g} s, sandbox_cpu)")
            if code == -signal.SIGXFSZ and self.confined is not None:
                return FmuError(f"{self.name}: {what} failed: its process wrote a file over its "
                                f"scratch folder's size ({self.confined.scratch_mb:g} MB)")
            how = (f"ended with {_signal_name(-code)}" if code < 0 else
                   f"exited with status {code}")
            return FmuError(f"{self.name}: {what} failed: its process {how}")
        message = self._request("fail", what)
        return FmuError(printable(message, ERROR_CHARS) if isinstance(message, str)
                        else f"{self.name}: {what} failed")

    def _hung(self, what: str, waited: float) -> FmuError:
        """A call that did not end within `waited` seconds: the child stopped."""
        self._timed_out = self._broken = True
        self._stop()
        which = "the step timeout of " if waited == self.timeout else ""
        return FmuError(f"{self.name}: {what} did not end within {which}{waited:g} s; its "
                        f"process was stopped")

    def close(self) -> None:
        """Let the child terminate and free the FMU, then release everything (safe twice)."""
        if self._process.poll() is None and not self._timed_out and self._proxy:
            library().proxy_post(self._proxy, EXIT)
            try:
                self._process.wait(CLOSE_WAIT)
            except subprocess.TimeoutExpired:
                warnings.warn(f"{self.name}: terminating and freeing it did not end within "
                              f"{CLOSE_WAIT:g} s; its process was stopped", stacklevel=2)
        self._stop()
        shutil.rmtree(self.scratch, ignore_errors=True)
        if self._proxy:
            library().proxy_free(self._proxy)
            self._proxy = None
        for fd in (self._cmd, self._ack, self._report, self._memory):
            if fd >= 0:
                os.close(fd)
        self._cmd = self._ack = self._report = self._memory = -1
        del self._view
        self._shared.close()

    def __enter__(self) -> IsolatedInstance:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the pipes ------------------------------------------------------------------------
    def _gone(self) -> bool:
        """Whether the child died or stopped answering."""
        return (self._timed_out or self._process.poll() is not None
                or library().proxy_failure(self._proxy) != 0)

    def _stop(self) -> None:
        if self._process.poll() is None:
            self._process.kill()
        self._process.wait()
        self._output.join(CLOSE_WAIT)
        if self._messages is not None:
            self._messages.join(CLOSE_WAIT)

    def _ended(self, what: str) -> FmuError:
        """The error for a child whose pipe closed: waited for, it died (fail names how), or,
        still alive, broke the protocol and is stopped. (fail asks a live child why; asking
        one whose pipe closed again would recurse while it is dying, not yet dead.)"""
        try:
            self._process.wait(CLOSE_WAIT)
        except subprocess.TimeoutExpired:
            return self._refused(what, "no answer but closed its pipe")
        return self.fail(what)

    def _refused(self, what: str, why: str) -> FmuError:
        """A child that broke the protocol: stopped, and named."""
        self._broken = True
        self._stop()
        return FmuError(f"{self.name}: {what} failed: its process sent {why}; it was stopped")

    def _request(self, what: str, *args: Any) -> Any:
        library().proxy_post(self._proxy, PYTHON)
        try:
            _send(self._cmd, [what, args])
        except OSError:
            raise self._ended(what) from None
        return self._response(what)

    def _response(self, what: str, timeout: float | None = None) -> Any:
        """The child's answer within `timeout` s (None: the step timeout): its value, or its
        error raised; a message over MESSAGE_LIMIT or not of the protocol's shape stops the
        child."""
        waited = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + waited
        length = LENGTH.unpack(self._read(LENGTH.size, what, deadline, waited))[0]
        if length > MESSAGE_LIMIT:
            raise self._refused(what, f"a message of {length} bytes (at most {MESSAGE_LIMIT})")
        try:
            status, value = _decoded(self._read(length, what, deadline, waited))
        except (ValueError, TypeError, RecursionError):  # RecursionError: nested too deep
            raise self._refused(what, "a message that is not the protocol's") from None
        if status == "error" and isinstance(value, str):
            raise FmuError(printable(value, ERROR_CHARS))
        if status != "ok":
            raise self._refused(what, "a message that is not the protocol's")
        return value

    def _read(self, size: int, what: str, deadline: float, waited: float) -> bytes:
        """`size` bytes from the child by `deadline` (time.monotonic; `waited` s after the
        request), into one buffer: a long message costs its length, once."""
        data = bytearray(size)
        view, got = memoryview(data), 0
        while got < size:
            ready, _, _ = select.select([self._ack], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                raise self._hung(what, waited)
            chunk = os.read(self._ack, min(size - got, 1 << 20))
            if not chunk:
                raise self._ended(what)
            view[got:got + len(chunk)] = chunk
            got += len(chunk)
        return bytes(data)


def confine_checks(folder: Path, report: int) -> None:
    """Confine this process (fmu.validation's checks) as an isolated FMU's child is: the
    sandbox's default limits, its environment, stdin, stdout and stderr on /dev/null, the
    sandbox's line on `report` (fmu.validation.Confine). The process must have one thread
    (fmu.child's `fresh` child), or the kernel refuses it the namespaces and Landlock binds
    only the calling thread."""
    lib = library()  # built (in the cache) with the caller's environment, where it is not yet
    python_path = os.environ.get("PYTHONPATH", "")
    os.environ.clear()
    os.environ.update(sandbox.environment(folder / "work", python_path))
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(null, fd)
    os.close(null)
    sandbox.enter(lib, folder, sandbox.DEFAULT, report)


def _read_exactly(fd: int, size: int) -> bytes:
    data = b""
    while len(data) < size:
        chunk = os.read(fd, size - len(data))
        if not chunk:
            raise EOFError
        data += chunk
    return data


def _answer(instance: FmuInstance, what: str, args: list[Any]) -> Any:
    if what not in REQUESTS:
        raise FmuError(f"unknown request {what!r}")
    if what == "fail":
        return str(instance.fail(*args))
    return getattr(instance, what)(*args)


def main(argv: Sequence[str]) -> int:
    """The child: unpack the FMU, enter the sandbox (if asked), load and instantiate the FMU,
    then serve the engine's calls (proxy_serve) and the master's requests until told to exit
    or the master is gone."""
    path, name, cmd, ack, memory, capacity, master, folder, report, options = argv
    die_with(int(master))  # a master killed while the FMU hangs takes it along
    for number in (signal.SIGINT, signal.SIGTERM):  # the master's to handle: it closes us
        signal.signal(number, signal.SIG_IGN)
    cmd_fd, ack_fd, capacity_n = int(cmd), int(ack), int(capacity)
    lib = library()
    shared = mmap.mmap(int(memory), lib.proxy_shared_size(capacity_n))
    address = ctypes.addressof(c_char.from_buffer(shared))
    given = json.loads(options)
    bounds = given["limits"]
    held: list[str] = []
    _send(ack_fd, ["ok", STARTED])

    def confine() -> None:
        held.extend(sandbox.enter(lib, Path(folder), sandbox.from_list(bounds), int(report)))

    try:
        instance = FmuInstance(read_fmu(path), name, given["solver"], Path(folder, "fmu"),
                               None if bounds is None else confine, given["scheduled"],
                               log=None if given["messages"] < 0
                               else message_writer(given["messages"]))
    except FmuError as error:
        _send(ack_fd, ["error", str(error)])
        return 1
    _send(ack_fd, ["ok", held])
    try:
        while lib.proxy_serve(address, capacity_n, instance.info.fmi_version == "3.0",
                              instance.component.value, *_functions(instance)) == SERVE_PYTHON:
            what, args = _decoded(_read_exactly(
                cmd_fd, LENGTH.unpack(_read_exactly(cmd_fd, LENGTH.size))[0]))
            try:
                _send(ack_fd, ["ok", _answer(instance, what, args)])
            except Exception as error:  # the master raises it as the FMU's error
                _send(ack_fd, ["error", str(error)])
    except (EOFError, BrokenPipeError):
        pass  # the master is gone
    finally:
        instance.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
