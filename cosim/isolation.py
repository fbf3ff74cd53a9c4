"""An FMU in its own process: a crash or a hang of the FMU ends the run with an error naming the
FMU, the call and the time, instead of taking the master with it (as libcosim's proxyfmu does).

IsolatedInstance stands where an FmuInstance does (cosim.master): the child process (`python -m
flexff.cosim.isolation`, this module's `main`) loads the FMU with the same importer
(fmu.importer.FmuInstance) and serves the engine's calls. The engine calls the proxy's
functions (cosim/c/proxy.c) through the FMU's plan as it calls an in-process FMU's own: each
call copies values through shared memory (a memfd both processes map) and makes one round trip
of a command byte over a pipe, so an isolated FMU costs a few microseconds more per call and
gives the same results bit for bit. Everything else (initialization, values of other types,
the FMU's messages) goes over the same pipes as pickled requests that the child's Python
answers. A call the child does not answer within the step timeout stops the child (SIGKILL);
one it dies in is reported with its signal. The child dies with its master, however the master
ends (fmu.orphans).
"""

from __future__ import annotations

import ctypes
import functools
import mmap
import os
import pickle
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from ctypes import c_char, c_double, c_int, c_long, c_size_t, c_void_p
from pathlib import Path
from typing import Any

from flexff.cosim import engine
from flexff.fmu import cache
from flexff.fmu.archive import UNPACKED
from flexff.fmu.compile import CFLAGS, compiler_version, run_compiler
from flexff.fmu.importer import FmuError, FmuInfo, FmuInstance, read_fmu
from flexff.fmu.orphans import die_with_parent

SOURCE = Path(__file__).parent / "c" / "proxy.c"
PYTHON, EXIT = b"P", b"X"  # commands proxy_serve hands back (CMD_PYTHON, CMD_EXIT in proxy.c)
SERVE_PYTHON = 1  # proxy_serve's result for a Python request
DIED, TIMED_OUT = 1, 2  # proxy_failure
CLOSE_WAIT = 10.0  # seconds a child has to terminate its FMU and exit after the run
START_WAIT = 60.0  # seconds at least that a child has to start Python and instantiate the FMU
REQUESTS = ("initialize", "set", "get", "fail", "network_times")  # what the child's Python does
LENGTH = struct.Struct("<Q")  # a pickled message's length prefix


@functools.cache
def library() -> ctypes.CDLL:
    """The compiled proxy, from the cache when its source and the compiler are unchanged."""
    key = cache.digest({SOURCE.name: SOURCE.read_text(),
                        engine.HEADER.name: engine.HEADER.read_text(),
                        "cflags": " ".join(CFLAGS), "compiler": compiler_version()})
    path = cache.cached_path(key, ".proxy.so")
    if not path.exists():
        with tempfile.TemporaryDirectory() as tmp:
            built = Path(tmp) / "proxy.so"
            run_compiler([SOURCE], built, [engine.HEADER.parent])
            cache.store(key, ".proxy.so", built)
    lib = ctypes.CDLL(str(path))
    lib.proxy_shared_size.argtypes, lib.proxy_shared_size.restype = [c_long], c_size_t
    lib.proxy_open.argtypes = [c_int, c_int, c_void_p, c_long, c_double]
    lib.proxy_open.restype = c_void_p
    lib.proxy_free.argtypes, lib.proxy_free.restype = [c_void_p], None
    lib.proxy_failure.argtypes, lib.proxy_failure.restype = [c_void_p], c_int
    lib.proxy_serve.argtypes = [c_int, c_int, c_void_p, c_long, c_int, c_void_p, c_void_p,
                                c_void_p, c_void_p]
    lib.proxy_serve.restype = c_int
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
    if instance.model_exchange:
        return [*functions, 0]
    return [*functions, engine.function_address(dll, "fmi3DoStep" if fmi3 else "fmi2DoStep")]


def _send(fd: int, message: Any) -> None:
    data = pickle.dumps(message)
    os.write(fd, LENGTH.pack(len(data)) + data)


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


class IsolatedInstance:
    """An FMU instantiated in a child process, with FmuInstance's interface for the master;
    `timeout` (s, None: none) bounds every call the child answers (its start, which includes
    starting Python, at least START_WAIT)."""

    def __init__(self, info: FmuInfo, name: str, timeout: float | None = None,
                 solver: str | None = None) -> None:
        self.info, self.name, self.timeout = info, name, timeout
        self.library = info.path
        self.initialized = False
        lib = library()
        self._capacity = max(1, len(info.variables))
        self._memory = os.memfd_create(f"flexff-{name}")
        os.ftruncate(self._memory, lib.proxy_shared_size(self._capacity))
        self._shared = mmap.mmap(self._memory, lib.proxy_shared_size(self._capacity))
        self._view = c_char.from_buffer(self._shared)
        cmd_read, self._cmd = os.pipe()
        self._ack, ack_write = os.pipe()
        root = str(Path(sys.modules["flexff"].__file__ or ".").resolve().parent.parent)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(
            [root, *filter(None, [os.environ.get("PYTHONPATH")])])}
        self._process = subprocess.Popen(
            [sys.executable, "-m", "flexff.cosim.isolation", str(info.path), name,
             str(cmd_read), str(ack_write), str(self._memory), str(self._capacity),
             solver or "", str(os.getpid())],
            pass_fds=(cmd_read, ack_write, self._memory), env=env)
        os.close(cmd_read)
        os.close(ack_write)
        self._proxy = lib.proxy_open(self._cmd, self._ack, ctypes.addressof(self._view),
                                     self._capacity, timeout or 0.0)
        self._timed_out = False
        self.scratch: Path | None = None  # the folder the child unpacked the FMU into
        try:
            self.scratch = _scratch(self._response("instantiating it",
                                                   max(START_WAIT, timeout or 0.0)))
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
        result: list[Any] = self._request("get", list(names))
        return result

    def network_times(self) -> dict[str, float] | None:
        if self._gone():
            return None
        times: dict[str, float] | None = self._request("network_times")
        return times

    def network_task(self) -> tuple[int, int] | None:
        """None: a network task's overrun counter lives in the child's memory, which the
        engine cannot read (the child's network_times still report its calls)."""
        return None

    def fail(self, what: str) -> FmuError:
        """The error for a failed call: the child's signal, the timeout, or the FMU's
        messages."""
        if self._timed_out or library().proxy_failure(self._proxy) == TIMED_OUT:
            self._stop()
            return FmuError(f"{self.name}: {what} did not end within the step timeout of "
                            f"{self.timeout:g} s; its process was stopped")
        if self._gone():
            code = self._process.wait(CLOSE_WAIT)
            how = (f"ended with {_signal_name(-code)}" if code < 0 else
                   f"exited with status {code}")
            return FmuError(f"{self.name}: {what} failed: its process {how}")
        return FmuError(self._request("fail", what))

    def close(self) -> None:
        """Let the child terminate and free the FMU, then release everything (safe twice)."""
        if self._process.poll() is None and not self._timed_out:
            try:
                os.write(self._cmd, EXIT)
                self._process.wait(CLOSE_WAIT)
            except (OSError, subprocess.TimeoutExpired):
                pass
        self._stop()
        if self.scratch is not None:  # a child that crashed or was stopped left it
            shutil.rmtree(self.scratch, ignore_errors=True)
        if self._proxy:
            library().proxy_free(self._proxy)
            self._proxy = None
        for fd in (self._cmd, self._ack, self._memory):
            if fd >= 0:
                os.close(fd)
        self._cmd = self._ack = self._memory = -1
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

    def _request(self, what: str, *args: Any) -> Any:
        data = pickle.dumps((what, args))
        try:
            os.write(self._cmd, PYTHON + LENGTH.pack(len(data)) + data)
        except OSError:
            raise self.fail(what) from None
        return self._response(what)

    def _response(self, what: str, timeout: float | None = None) -> Any:
        timeout = timeout or self.timeout
        length = LENGTH.unpack(self._read(LENGTH.size, what, timeout))[0]
        status, value = pickle.loads(self._read(length, what, timeout))
        if status == "error":
            raise FmuError(value)
        return value

    def _read(self, size: int, what: str, timeout: float | None) -> bytes:
        data = b""
        while len(data) < size:
            ready, _, _ = select.select([self._ack], [], [], timeout)
            if not ready:
                self._timed_out = True
                raise self.fail(what)
            chunk = os.read(self._ack, size - len(data))
            if not chunk:
                raise self.fail(what)
            data += chunk
        return data


def _scratch(reported: Any) -> Path | None:
    """The folder a child says it unpacked its FMU into, if it is one the importer makes (a
    child is never trusted to name another folder for its master to remove)."""
    path = Path(str(reported))
    made = path.parent == Path(tempfile.gettempdir()) and path.name.startswith(UNPACKED)
    return path if made and not path.is_symlink() else None


def _read_exactly(fd: int, size: int) -> bytes:
    data = b""
    while len(data) < size:
        chunk = os.read(fd, size - len(data))
        if not chunk:
            raise EOFError
        data += chunk
    return data


def _answer(instance: FmuInstance, what: str, args: tuple[Any, ...]) -> Any:
    if what not in REQUESTS:
        raise FmuError(f"unknown request {what!r}")
    if what == "fail":
        return str(instance.fail(*args))
    return getattr(instance, what)(*args)


def main(argv: Sequence[str]) -> int:
    """The child: instantiate the FMU, then serve the engine's calls (proxy_serve) and the
    master's Python requests until told to exit or the master is gone."""
    path, name, cmd, ack, memory, capacity, solver, master = argv
    die_with_parent(int(master))  # a master killed while the FMU hangs takes it along
    for number in (signal.SIGINT, signal.SIGTERM):  # the master's to handle: it closes us
        signal.signal(number, signal.SIG_IGN)
    cmd_fd, ack_fd, capacity_n = int(cmd), int(ack), int(capacity)
    lib = library()
    shared = mmap.mmap(int(memory), lib.proxy_shared_size(capacity_n))
    address = ctypes.addressof(c_char.from_buffer(shared))
    try:
        instance = FmuInstance(read_fmu(path), name, solver or None)
    except FmuError as error:
        _send(ack_fd, ("error", str(error)))
        return 1
    _send(ack_fd, ("ok", str(instance.scratch)))
    try:
        while lib.proxy_serve(cmd_fd, ack_fd, address, capacity_n,
                              instance.info.fmi_version == "3.0", instance.component.value,
                              *_functions(instance)) == SERVE_PYTHON:
            what, args = pickle.loads(_read_exactly(
                cmd_fd, LENGTH.unpack(_read_exactly(cmd_fd, LENGTH.size))[0]))
            try:
                _send(ack_fd, ("ok", _answer(instance, what, args)))
            except Exception as error:  # the master raises it as the FMU's error
                _send(ack_fd, ("error", str(error)))
    except (EOFError, BrokenPipeError):
        pass  # the master is gone
    finally:
        instance.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
