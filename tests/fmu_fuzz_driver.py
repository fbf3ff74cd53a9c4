"""FMI 2.0 call-sequence fuzzer: seeded random call sequences against one co-simulation FMU.

tests/fmu/test_fuzz.py runs it in a subprocess, so that a crash, a hang or a sanitizer report
of the FMU fails the test instead of the test run:

    python tests/fmu_fuzz_driver.py SPEC.json --seed S --count N --trace FILE

SPEC.json (test_fmu_fuzz.fuzz_spec) names the FMU's shared library, GUID and resources, its
variables by role with start values and a typical scale, the precomputation table of a
feedforward in the precomputed mode, and another FMU ("foreign") whose states and serialized
states are offered to this one. Sequence i is drawn from random.Random(S + i): since the FMU
is deterministic, `--seed S --count 1 --trace /dev/stdout` replays a sequence call by call.
FILE holds the calls of the current sequence, each written before it is made, so that after a
crash or a hang it ends with the culprit.

A sequence mixes valid calls (setup, initialization, inputs that follow the reference,
steps of the default size, FMU states that are saved, serialized and restored, also into
instances that were never initialized) with invalid ones: calls out of order, unknown value
references, null arrays, non-finite and huge values, steps of size 0, negative, NaN, tiny and
huge, wrong communication points, freed and foreign states, serialized states corrupted by
flipped bytes, truncation and overwritten counters, freed and garbage component pointers.
Any status is acceptable (an error is the right answer to a bad call); the driver fails (exit
status 3, the reason on stdout) only where the FMU breaks its own contract:
  - a status outside fmi2OK .. fmi2Pending;
  - fmi2Error from a live instance whose error logging is on, without an error message;
  - a state the FMU itself produced that it refuses to restore or to deserialize.
Crashes, hangs and sanitizer reports are judged by the caller.

Only the standard library: the binary is called through ctypes as a C master calls it, in a
process that may run under a sanitizer runtime (LD_PRELOAD).
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import random
import re
import struct
import sys
import time
from ctypes import (
    CFUNCTYPE,
    POINTER,
    Structure,
    addressof,
    byref,
    c_char,
    c_char_p,
    c_double,
    c_int,
    c_size_t,
    c_uint,
    c_void_p,
    cast,
    create_string_buffer,
)

OK, WARNING, DISCARD, ERROR, FATAL, PENDING = range(6)
CO_SIMULATION = 1
LAST_SUCCESSFUL_TIME = 2
CATEGORIES = (b"logStatusError", b"logStatusWarning", b"logAll")

LOGGER = CFUNCTYPE(None, c_void_p, c_char_p, c_int, c_char_p, c_char_p)
ALLOCATE = CFUNCTYPE(c_void_p, c_size_t, c_size_t)
FREE = CFUNCTYPE(None, c_void_p)
STEP_FINISHED = CFUNCTYPE(None, c_void_p, c_int)


class Callbacks(Structure):
    _fields_ = [("logger", LOGGER), ("allocateMemory", ALLOCATE), ("freeMemory", FREE),
                ("stepFinished", STEP_FINISHED), ("componentEnvironment", c_void_p)]


P_UINT, P_DOUBLE, P_INT, P_CHARP, P_VOIDP = (POINTER(c_uint), POINTER(c_double), POINTER(c_int),
                                             POINTER(c_char_p), POINTER(c_void_p))
SIGNATURES = {
    "fmi2GetTypesPlatform": (c_char_p, []),
    "fmi2GetVersion": (c_char_p, []),
    "fmi2SetDebugLogging": (c_int, [c_void_p, c_int, c_size_t, P_CHARP]),
    "fmi2Instantiate": (c_void_p, [c_char_p, c_int, c_char_p, c_char_p, POINTER(Callbacks),
                                   c_int, c_int]),
    "fmi2FreeInstance": (None, [c_void_p]),
    "fmi2SetupExperiment": (c_int, [c_void_p, c_int, c_double, c_double, c_int, c_double]),
    "fmi2EnterInitializationMode": (c_int, [c_void_p]),
    "fmi2ExitInitializationMode": (c_int, [c_void_p]),
    "fmi2Terminate": (c_int, [c_void_p]),
    "fmi2Reset": (c_int, [c_void_p]),
    "fmi2GetReal": (c_int, [c_void_p, P_UINT, c_size_t, P_DOUBLE]),
    "fmi2GetInteger": (c_int, [c_void_p, P_UINT, c_size_t, P_INT]),
    "fmi2GetBoolean": (c_int, [c_void_p, P_UINT, c_size_t, P_INT]),
    "fmi2GetString": (c_int, [c_void_p, P_UINT, c_size_t, P_CHARP]),
    "fmi2SetReal": (c_int, [c_void_p, P_UINT, c_size_t, P_DOUBLE]),
    "fmi2SetInteger": (c_int, [c_void_p, P_UINT, c_size_t, P_INT]),
    "fmi2SetBoolean": (c_int, [c_void_p, P_UINT, c_size_t, P_INT]),
    "fmi2SetString": (c_int, [c_void_p, P_UINT, c_size_t, P_CHARP]),
    "fmi2GetFMUstate": (c_int, [c_void_p, P_VOIDP]),
    "fmi2SetFMUstate": (c_int, [c_void_p, c_void_p]),
    "fmi2FreeFMUstate": (c_int, [c_void_p, P_VOIDP]),
    "fmi2SerializedFMUstateSize": (c_int, [c_void_p, c_void_p, POINTER(c_size_t)]),
    "fmi2SerializeFMUstate": (c_int, [c_void_p, c_void_p, POINTER(c_char), c_size_t]),
    "fmi2DeSerializeFMUstate": (c_int, [c_void_p, POINTER(c_char), c_size_t, P_VOIDP]),
    "fmi2GetDirectionalDerivative": (c_int, [c_void_p, P_UINT, c_size_t, P_UINT, c_size_t,
                                             P_DOUBLE, P_DOUBLE]),
    "fmi2SetRealInputDerivatives": (c_int, [c_void_p, P_UINT, c_size_t, P_INT, P_DOUBLE]),
    "fmi2GetRealOutputDerivatives": (c_int, [c_void_p, P_UINT, c_size_t, P_INT, P_DOUBLE]),
    "fmi2DoStep": (c_int, [c_void_p, c_double, c_double, c_int]),
    "fmi2CancelStep": (c_int, [c_void_p]),
    "fmi2GetStatus": (c_int, [c_void_p, c_int, P_INT]),
    "fmi2GetRealStatus": (c_int, [c_void_p, c_int, P_DOUBLE]),
    "fmi2GetIntegerStatus": (c_int, [c_void_p, c_int, P_INT]),
    "fmi2GetBooleanStatus": (c_int, [c_void_p, c_int, P_INT]),
    "fmi2GetStringStatus": (c_int, [c_void_p, c_int, P_CHARP]),
}

SPECIAL_REALS = (0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 5e-324, 1e300, -1e300, math.inf,
                 -math.inf, math.nan, 2.0**63, 1e-3, -1e-3)
SPECIAL_INTS = (0, 1, -1, 2**31 - 1, -2**31, 12345)
INT64_WORDS = (0, 1, -1, 2, 3, 4, 7, 2**31, 2**32, 2**62, -2**63, 2**63 - 1)
DOUBLE_WORDS = (math.nan, math.inf, -math.inf, -1e300, 1e300, 0.0, -1.0)

ERROR_KIND = re.compile(r"'[^' ]*'|-?nan|-?inf|(?<![\w.])[-+]?[0-9][-+0-9.e]*")  # summary
_messages: list[tuple[int, bytes]] = []  # (status, message) of the log calls of a sequence


@LOGGER
def _logger(env, instance, status, category, message):
    _messages.append((status, message or b""))


class Violation(Exception):
    """The FMU broke its own contract (see the module docstring)."""


class Library:
    """The fmi2 functions of one shared library, typed."""

    def __init__(self, path: str):
        self.dll = ctypes.CDLL(path)
        for name, (restype, argtypes) in SIGNATURES.items():
            function = getattr(self.dll, name)
            function.restype, function.argtypes = restype, argtypes


def callbacks(logger: bool = True, allocate: bool = True) -> Callbacks:
    """Callbacks with the C library's calloc and free (the sanitizer's, when one is loaded)."""
    libc = ctypes.CDLL(None)
    return Callbacks(
        _logger if logger else cast(None, LOGGER),
        ALLOCATE(cast(libc.calloc, c_void_p).value) if allocate else cast(None, ALLOCATE),
        FREE(cast(libc.free, c_void_p).value), cast(None, STEP_FINISHED), None)


class Tracer:
    """The calls of the current sequence, in a file, each line written before the call."""

    def __init__(self, path: str):
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self.regular = os.path.isfile(path)

    def restart(self, seed: int) -> None:
        if self.regular:
            os.ftruncate(self.fd, 0)
            os.lseek(self.fd, 0, os.SEEK_SET)
        self.write(f"# seed {seed}\n")

    def write(self, text: str) -> None:
        os.write(self.fd, text.encode())


class Instance:
    """One component pointer handed out by fmi2Instantiate, and what the FMU was told of it."""

    def __init__(self, pointer: int, logger: bool):
        self.pointer = pointer
        self.logger = logger
        self.log_errors = logger  # on, if there is a logger, until fmi2SetDebugLogging says no


class Fuzzer:
    """What the sequences of one process share: the library, a janitor instance that frees
    left-over FMU states, the foreign FMU's state and serialized state. Nothing else carries
    over from one sequence to the next, so that a seed replays on its own."""

    def __init__(self, spec: dict, tracer: Tracer):
        self.spec, self.tracer = spec, tracer
        self.lib = Library(spec["library"])
        self.cb = callbacks()
        self.cb_nolog, self.cb_noalloc = callbacks(logger=False), callbacks(allocate=False)
        self.reals = spec["reals"]
        self.by_role = {role: [v for v in self.reals if v["role"] == role]
                        for role in ("parameter", "max_substep", "input", "output", "state")}
        self.n_real = spec["n_real"]
        self.table = spec.get("table")
        self.step = spec["step"]
        self.calls = 0
        self.statuses = [0] * 6
        self.errors: dict[str, int] = {}  # error messages, numbers and names left out: counts
        self.janitor = self._instantiate(self.lib, spec, "janitor")
        self.foreign_state, self.foreign_blob = self._foreign(spec.get("foreign"))
        self.counters = self._counters()

    @staticmethod
    def _instantiate(lib: Library, spec: dict, name: str) -> int:
        pointer = lib.dll.fmi2Instantiate(name.encode(), CO_SIMULATION, spec["guid"].encode(),
                                          spec["resources"].encode(), byref(callbacks()), 0, 0)
        if not pointer:
            raise RuntimeError(f"cannot instantiate {spec['library']}: "
                               f"{[m for _, m in _messages[-3:]]}")
        return pointer

    @staticmethod
    def _state(lib: Library, comp: int) -> tuple[c_void_p, bytes]:
        """A new FMU state of the instance `comp`, and its serialized form."""
        dll, state, size = lib.dll, c_void_p(), c_size_t()
        dll.fmi2GetFMUstate(comp, byref(state))
        dll.fmi2SerializedFMUstateSize(comp, state, byref(size))
        buffer = create_string_buffer(size.value)
        dll.fmi2SerializeFMUstate(comp, state, buffer, size.value)
        return state, buffer.raw

    def _blob(self, comp: int) -> bytes:
        state, blob = self._state(self.lib, comp)
        self.lib.dll.fmi2FreeFMUstate(comp, byref(state))
        return blob

    def _counters(self) -> list[int]:
        """Where the serialized state holds a counter (an int64 that one step increments, such
        as the network's step counter): the states before and after one step, compared."""
        dll = self.lib.dll
        comp = self._instantiate(self.lib, self.spec, "probe")
        dll.fmi2SetupExperiment(comp, 0, 0.0, 0.0, 0, 0.0)
        dll.fmi2EnterInitializationMode(comp)
        dll.fmi2ExitInitializationMode(comp)
        inputs = self.by_role["input"]
        row = self.table[0][1:] if self.table else [v["start"] for v in inputs]
        dll.fmi2SetReal(comp, (c_uint * len(inputs))(*[v["vr"] for v in inputs]), len(inputs),
                        (c_double * len(inputs))(*row))
        before = self._blob(comp)
        dll.fmi2DoStep(comp, 0.0, self.step, 1)
        after = self._blob(comp)
        dll.fmi2FreeInstance(comp)
        return [k for k in range(24, len(before) - 7, 8)
                if struct.unpack_from("<q", after, k)[0] - struct.unpack_from("<q", before, k)[0]
                == 1]

    def _foreign(self, spec: dict | None) -> tuple[int | None, bytes | None]:
        """A state and a serialized state of another FMU, initialized and stepped once."""
        if not spec:
            return None, None
        lib = Library(spec["library"])
        comp = self._instantiate(lib, spec, "foreign")
        dll = lib.dll
        dll.fmi2SetupExperiment(comp, 0, 0.0, 0.0, 0, 0.0)
        dll.fmi2EnterInitializationMode(comp)
        dll.fmi2ExitInitializationMode(comp)
        dll.fmi2DoStep(comp, 0.0, spec["step"], 1)
        state, blob = self._state(lib, comp)
        self.foreign_lib = lib  # kept loaded, its instance alive, for the whole process
        return state.value, blob

    # -- one call ---------------------------------------------------------------------------
    def call(self, name: str, comp, args: tuple, shown: str, live: dict[int, Instance]) -> int:
        """Call fmi2<name>(comp, *args), traced, and check the status against the contract."""
        self.tracer.write(f"{name}({_hex(comp)}{', ' if shown else ''}{shown})")
        before = len(_messages)
        status = getattr(self.lib.dll, name)(comp, *args)
        self.last_errors = [m.decode(errors="replace") for s, m in _messages[before:] if s >= ERROR]
        self.calls += 1
        self.tracer.write(f" -> {status}\n")
        if not 0 <= status <= PENDING:
            raise Violation(f"{name} returned the status {status}, which FMI 2.0 does not have")
        self.statuses[status] += 1
        instance = live.get(comp or 0)
        if status >= ERROR and instance is not None and instance.log_errors and not any(
                s >= ERROR for s, _ in _messages[before:]):
            raise Violation(f"{name} returned {status} without an error message")
        return status


def _hex(pointer) -> str:
    return "NULL" if not pointer else f"{pointer:#x}"


def _reals(values) -> str:
    return "[" + ", ".join(repr(v) for v in values) + "]"


class Sequence:
    """One random sequence of calls: instances, FMU states and blobs of this sequence."""

    def __init__(self, fuzzer: Fuzzer, seed: int):
        self.f, self.rng = fuzzer, random.Random(seed)
        self.instances: list[Instance] = []  # every pointer handed out, freed ones included
        self.live: dict[int, Instance] = {}  # by address: what a pointer reaches now
        self.states: list[int] = []
        self.blobs: list[bytes] = []
        self.count = 0

    def run(self) -> None:
        rng = self.rng
        _messages.clear()
        self.instantiate(good=True)
        actions, weights = zip(*ACTIONS)
        for _ in range(rng.randint(5, 60)):
            rng.choices(actions, weights)[0](self)
        self.cleanup()
        for status, message in _messages:
            if status >= ERROR:
                kind = ERROR_KIND.sub("#", message.decode(errors="replace"))[:120]
                self.f.errors[kind] = self.f.errors.get(kind, 0) + 1

    # -- helpers ----------------------------------------------------------------------------
    def call(self, name: str, comp, *args, shown: str = "") -> int:
        return self.f.call(name, comp, args, shown, self.live)

    def component(self) -> int | None:
        """Mostly a live instance; sometimes a freed one, NULL or garbage."""
        rng = self.rng
        live = list(self.live.values())
        r = rng.random()
        if live and r < 0.92:
            return rng.choice(live).pointer
        freed = [i.pointer for i in self.instances if i.pointer not in self.live]
        if freed and r < 0.97:
            return rng.choice(freed)
        return self.garbage_pointer()

    def garbage_pointer(self) -> int | None:
        rng = self.rng
        choice = rng.randrange(4)
        if choice == 0:
            return None
        if choice == 1:
            return rng.choice((1, 0x10, 0x1000, 2**47 - 8))  # never dereferenced by the FMU
        self._garbage = create_string_buffer(rng.randbytes(256))  # a readable fake instance
        return addressof(self._garbage)

    def time_of(self, comp) -> float:
        """The FMU's current time (fmi2LastSuccessfulTime), or 0 where it has none."""
        value = c_double()
        status = self.call("fmi2GetRealStatus", comp, LAST_SUCCESSFUL_TIME, byref(value),
                           shown="fmi2LastSuccessfulTime")
        return value.value if status == OK else 0.0

    def real_value(self, var: dict) -> float:
        rng = self.rng
        if var["role"] == "max_substep":  # never a value that makes one step take seconds
            return rng.choice((var["start"], var["start"] * 4, var["start"] / 2, 1.0, 1e300,
                               1e-300, 0.0, -1.0, math.nan, math.inf))
        r = rng.random()
        if r < 0.5:
            return var["start"] + var["scale"] * rng.gauss(0.0, 1.0)
        if r < 0.65:
            return var["start"]
        if r < 0.75:
            return var["scale"] * 10 ** rng.uniform(-3, 3) * rng.choice((1, -1))
        return rng.choice(SPECIAL_REALS)

    def value_references(self, pool: list[dict], n: int) -> list[int]:
        """n value references, mostly from `pool`, sometimes any Real or an unknown one."""
        rng = self.rng
        out = []
        for _ in range(n):
            r = rng.random()
            if pool and r < 0.8:
                out.append(rng.choice(pool)["vr"])
            elif r < 0.93:
                out.append(rng.choice(self.f.reals)["vr"])
            else:
                out.append(rng.choice((self.f.n_real, self.f.n_real + 7, 2**32 - 1, 2**31)))
        return out

    def arrays(self, vrs: list[int], ctype, values=None):
        """ctypes arrays for vrs and values; sometimes NULL (with nvr > 0: an error)."""
        n = len(vrs)
        if n and self.rng.random() < 0.05:
            return None, None
        vr = (c_uint * max(n, 1))(*vrs)
        val = (ctype * max(n, 1))(*(values or []))
        return vr, val

    def row_inputs(self, comp, exact: bool = False) -> list[float] | None:
        """The reference inputs at the FMU's current time: the table row (precomputed mode;
        unless `exact`, sometimes the next or previous one), else start values with a little
        noise."""
        rng = self.rng
        inputs = self.f.by_role["input"]
        if self.f.table:
            k = (self.time_of(comp) - self.f.table[0][0]) / self.f.step
            k = round(k) if math.isfinite(k) else 0
            k += 0 if exact else rng.choice((0,) * 12 + (-1, 1))
            row = self.f.table[min(max(k, 0), len(self.f.table) - 1)]
            return list(row[1:])
        return [v["start"] + 0.3 * v["scale"] * rng.gauss(0.0, 1.0) for v in inputs]

    # -- actions: life cycle ----------------------------------------------------------------
    def instantiate(self, good: bool = False) -> None:
        rng, spec = self.rng, self.f.spec
        if len(self.live) >= 3 and not good:
            return
        name, kind, guid = f"fuzz{self.count}".encode(), CO_SIMULATION, spec["guid"].encode()
        resources, cb, logs = spec["resources"].encode(), self.f.cb, True
        variant = "good" if good or rng.random() < 0.8 else rng.choice(
            ("guid", "name", "no name", "type", "no callbacks", "no logger", "no allocator",
             "resources", "no resources"))
        if variant == "guid":
            guid = b"{00000000-0000-0000-0000-000000000001}"
        elif variant == "name":
            name = b""
        elif variant == "no name":
            name = None
        elif variant == "type":
            kind = 0
        elif variant == "no logger":
            cb, logs = self.f.cb_nolog, False
        elif variant == "no allocator":
            cb = self.f.cb_noalloc
        elif variant == "resources":
            resources = rng.choice((b"file:///no/such/folder", b"http://example.com/r", b""))
        elif variant == "no resources":
            resources = None
        self.count += 1
        self.f.tracer.write(f"fmi2Instantiate({name!r}, {kind}, {variant})")
        before = len(_messages)
        pointer = self.f.lib.dll.fmi2Instantiate(
            name, kind, guid, resources, None if variant == "no callbacks" else byref(cb), 0,
            int(rng.random() < 0.2))
        self.f.calls += 1
        self.f.tracer.write(f" -> {_hex(pointer)}\n")
        if pointer:
            instance = Instance(pointer, logs)
            self.instances.append(instance)
            self.live[pointer] = instance
        elif variant == "good":
            raise Violation(f"fmi2Instantiate failed: {_messages[before:]}")
        elif logs and variant != "no callbacks" and len(_messages) == before:
            raise Violation(f"fmi2Instantiate ({variant}) returned NULL without a message")

    def free_instance(self) -> None:
        comp = self.component()
        self.f.tracer.write(f"fmi2FreeInstance({_hex(comp)})")
        self.f.lib.dll.fmi2FreeInstance(comp)
        self.f.calls += 1
        self.f.tracer.write("\n")
        self.live.pop(comp or 0, None)

    def setup(self) -> None:
        rng = self.rng
        start = 0.0 if rng.random() < 0.8 else rng.choice(SPECIAL_REALS)
        stop_defined = rng.random() < 0.4
        stop = start + self.f.step * rng.choice((0, 1, 5, 40, 1000, -1)) \
            if rng.random() < 0.8 else rng.choice(SPECIAL_REALS)
        self.call("fmi2SetupExperiment", self.component(), rng.randrange(2), 1e-6, start,
                  int(stop_defined), stop, shown=f"start={start!r}, stop={stop!r} "
                                                 f"(defined {stop_defined})")

    def enter_init(self) -> None:
        self.call("fmi2EnterInitializationMode", self.component())

    def exit_init(self) -> None:
        self.call("fmi2ExitInitializationMode", self.component())

    def initialize(self) -> None:
        """The usual path to stepping: setup at 0, initialization with a few values set."""
        comp = self.component()
        self.call("fmi2SetupExperiment", comp, 0, 0.0, 0.0, 0, 0.0, shown="start=0")
        self.call("fmi2EnterInitializationMode", comp)
        if self.rng.random() < 0.5:
            self.set_inputs(comp)
        if self.rng.random() < 0.3:
            self.set_real(comp)
        self.call("fmi2ExitInitializationMode", comp)

    def terminate(self) -> None:
        self.call("fmi2Terminate", self.component())

    def reset(self) -> None:
        self.call("fmi2Reset", self.component())

    # -- actions: variables -----------------------------------------------------------------
    def set_real(self, comp=None) -> None:
        rng = self.rng
        comp = comp or self.component()
        settable = self.f.by_role["parameter"] + self.f.by_role["max_substep"] + \
            self.f.by_role["input"]
        vrs = self.value_references(settable, rng.randint(0, 4))
        by_vr = {v["vr"]: v for v in self.f.reals}
        values = [self.real_value(by_vr[vr]) if vr in by_vr else rng.choice(SPECIAL_REALS)
                  for vr in vrs]
        vr, val = self.arrays(vrs, c_double, values)
        self.call("fmi2SetReal", comp, vr, len(vrs), val, shown=f"{vrs}, {_reals(values)}")

    def set_inputs(self, comp=None, exact: bool = False) -> None:
        comp = comp or self.component()
        values = self.row_inputs(comp, exact)
        vrs = [v["vr"] for v in self.f.by_role["input"]]
        vr, val = (c_uint * max(len(vrs), 1))(*vrs), (c_double * max(len(vrs), 1))(*values)
        self.call("fmi2SetReal", comp, vr, len(vrs), val, shown=f"inputs {_reals(values)}")

    def get_real(self, comp=None) -> None:
        rng = self.rng
        comp = comp or self.component()
        vrs = self.value_references(self.f.by_role["output"] + self.f.by_role["state"],
                                    rng.randint(0, 5))
        vr, val = self.arrays(vrs, c_double)
        self.call("fmi2GetReal", comp, vr, len(vrs), val, shown=f"{vrs}")

    def integers(self) -> None:
        rng = self.rng
        vrs = [self.f.spec["seed_vr"] if rng.random() < 0.8 else
               rng.choice((0, self.f.n_real + 5, 2**32 - 1)) for _ in range(rng.randint(0, 2))]
        values = [rng.choice(SPECIAL_INTS) for _ in vrs]
        vr, val = self.arrays(vrs, c_int, values)
        name = rng.choice(("fmi2SetInteger", "fmi2GetInteger"))
        self.call(name, self.component(), vr, len(vrs), val, shown=f"{vrs}, {values}")

    def booleans_and_strings(self) -> None:
        rng = self.rng
        name = rng.choice(("fmi2GetBoolean", "fmi2SetBoolean", "fmi2GetString", "fmi2SetString"))
        vrs = [rng.randrange(self.f.n_real + 2) for _ in range(rng.randint(0, 1))]
        ctype = c_int if "Boolean" in name else c_char_p
        vr, val = self.arrays(vrs, ctype, [1 if ctype is c_int else b"x"] * len(vrs))
        self.call(name, self.component(), vr, len(vrs), val, shown=f"{vrs}")

    # -- actions: stepping ------------------------------------------------------------------
    def step_size(self) -> float:
        rng, h = self.rng, self.f.step
        if rng.random() < 0.75:
            return h
        return rng.choice((0.0, -h, 2 * h, h * (1 + 1e-12), h * (1 + 1e-6), 1e-12, 0.05, 1e9,
                           1e300, math.inf, math.nan, 5e-324, -0.0))

    def do_step(self) -> None:
        rng = self.rng
        comp = self.component()
        t = self.time_of(comp)
        if rng.random() < 0.1:
            t = rng.choice((t + self.f.step, t - self.f.step, 0.0, math.nan, -1.0, 1e300))
        h = self.step_size()
        self.call("fmi2DoStep", comp, t, h, rng.randrange(2), shown=f"t={t!r}, h={h!r}")

    def run_steps(self) -> None:
        """Up to 60 steps with valid inputs (deep into the run: call points, table's end)."""
        rng = self.rng
        comp = self.component()
        outputs = [v["vr"] for v in self.f.by_role["output"]]
        for _ in range(rng.randint(1, 60)):
            self.set_inputs(comp, exact=True)
            if outputs and rng.random() < 0.5:
                vr = (c_uint * len(outputs))(*outputs)
                self.call("fmi2GetReal", comp, vr, len(outputs), (c_double * len(outputs))(),
                          shown="outputs")
            t = self.time_of(comp)
            if self.call("fmi2DoStep", comp, t, self.f.step, 1, shown=f"t={t!r}, h=step") != OK:
                return

    # -- actions: FMU states ----------------------------------------------------------------
    def pick_state(self) -> c_void_p:
        """A state of this sequence, the foreign FMU's, or NULL (a copy: the callee may write)."""
        rng = self.rng
        r = rng.random()
        if self.states and r < 0.85:
            return c_void_p(rng.choice(self.states))
        if self.f.foreign_state and r < 0.95:
            return c_void_p(self.f.foreign_state)
        return c_void_p()

    def get_state(self) -> None:
        rng = self.rng
        comp = self.component()
        reuse = self.states and rng.random() < 0.3
        state = self.pick_state() if reuse else c_void_p()
        target = None if rng.random() < 0.03 else byref(state)
        status = self.call("fmi2GetFMUstate", comp, target, shown=_hex(state.value))
        if status == OK and state.value not in self.states:
            self.states.append(state.value)
        restore = status == OK and rng.random() < 0.3  # a state just taken must restore
        if restore and self.call("fmi2SetFMUstate", comp, state, shown=_hex(state.value)) != OK:
            raise Violation("fmi2SetFMUstate refused the state fmi2GetFMUstate just gave: "
                            f"{self.f.last_errors}")

    def set_state(self) -> None:
        state = self.pick_state()
        self.call("fmi2SetFMUstate", self.component(), state, shown=_hex(state.value))

    def free_state(self) -> None:
        state = self.pick_state()
        before = state.value
        status = self.call("fmi2FreeFMUstate", self.component(), byref(state),
                           shown=_hex(before))
        if status == OK and before in self.states:
            self.states.remove(before)  # freed: never handed to the FMU again

    def serialize(self) -> None:
        rng = self.rng
        if not self.states:
            self.get_state()
        comp, state = self.component(), self.pick_state()
        size = c_size_t()
        status = self.call("fmi2SerializedFMUstateSize", comp, state,
                           None if rng.random() < 0.03 else byref(size), shown=_hex(state.value))
        if status != OK:
            return
        n = size.value + rng.choice((0,) * 10 + (-1, 1, -size.value))
        buffer = create_string_buffer(max(n, 1))
        status = self.call("fmi2SerializeFMUstate", comp, state,
                           None if rng.random() < 0.03 else buffer, n,
                           shown=f"{_hex(state.value)}, size={n}")
        if status != OK:
            return
        blob = buffer.raw[:n]
        self.blobs.append(blob)
        restored = c_void_p()  # what the FMU wrote it must read back
        data = (c_char * n).from_buffer_copy(blob)
        if self.call("fmi2DeSerializeFMUstate", comp, data, n, byref(restored),
                     shown="the blob just written") != OK:
            raise Violation("fmi2DeSerializeFMUstate refused a blob fmi2SerializeFMUstate wrote: "
                            f"{self.f.last_errors}")
        self.call("fmi2FreeFMUstate", comp, byref(restored), shown=_hex(restored.value))

    def deserialize(self) -> None:
        rng = self.rng
        if not self.blobs:
            self.serialize()
        sources = list(self.blobs)
        if self.f.foreign_blob and (not sources or rng.random() < 0.1):
            sources = [self.f.foreign_blob]
        if not sources:
            return
        blob, how = self.corrupt(rng.choice(sources))
        comp = self.component()
        state = self.pick_state() if self.states and rng.random() < 0.2 else c_void_p()
        data = (c_char * max(len(blob), 1)).from_buffer_copy(blob or b"\0")
        status = self.call("fmi2DeSerializeFMUstate", comp, data if blob or rng.random() < 0.5
                           else None, len(blob), byref(state),
                           shown=f"{len(blob)} bytes ({how}), into {_hex(state.value)}")
        if status == OK:
            if state.value not in self.states:
                self.states.append(state.value)
            if rng.random() < 0.7:
                self.call("fmi2SetFMUstate", self.component(), state, shown=_hex(state.value))

    def corrupt(self, blob: bytes) -> tuple[bytes, str]:
        """The blob, or a damaged copy, and what was done to it."""
        rng = self.rng
        if rng.random() < 0.4:
            return blob, "intact"
        data = bytearray(blob)
        how = rng.choice(("flip", "truncate", "extend", "word", "int", "header", "zeros")
                         + ("counter",) * 2 * bool(self.f.counters))
        if how == "counter":  # a counter moved: in range, at the end of the table, past it
            offset = rng.choice(self.f.counters)
            value = struct.unpack_from("<q", data, offset)[0]
            rows = len(self.f.table or ())
            value = rng.choice((value + 1, value - 1, value + 4, rows - 1, rows, rows + 1,
                                rows + 3, -1, -4, 2**31, 2**62, -2**63))
            data[offset:offset + 8] = struct.pack("<q", value)
            how = f"counter at {offset} = {value}"
        elif how == "flip":
            for _ in range(rng.randint(1, 4)):
                data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        elif how == "truncate":
            del data[rng.randrange(len(data)):]
        elif how == "extend":
            data += rng.randbytes(rng.randint(1, 16))
        elif how in ("word", "int"):  # an aligned field of the state overwritten: a counter,
            header = 24                # a time, a mode, a value
            offset = header + 4 * rng.randrange(max((len(data) - header) // 4 - 1, 1))
            if how == "int":
                word = struct.pack("<i", rng.choice((*SPECIAL_INTS, 4, 8, 16, 1 << 5)))
            elif rng.random() < 0.5:
                offset -= offset % 8
                size = len(self.f.table or ())
                word = struct.pack("<q", rng.choice((*INT64_WORDS, size, size - 1)))
            else:
                offset -= offset % 8
                word = struct.pack("<d", rng.choice(DOUBLE_WORDS))
            data[offset:offset + len(word)] = word
            how = f"{how} at {offset}"
        elif how == "header":
            data[rng.randrange(min(24, len(data)))] ^= 0xFF
        else:
            data[24:] = bytes(len(data) - 24)
        return bytes(data), how

    # -- actions: the rest of the API -------------------------------------------------------
    def debug_logging(self) -> None:
        rng = self.rng
        comp = self.component()
        on = rng.randrange(2)
        r = rng.random()
        if r < 0.3:
            names = []
        elif r < 0.85:
            names = rng.sample(CATEGORIES, rng.randint(1, 3))
        else:
            names = [b"noSuchCategory"]
        array = (c_char_p * max(len(names), 1))(*names)
        null = names and rng.random() < 0.1
        status = self.call("fmi2SetDebugLogging", comp, on, len(names), None if null else array,
                           shown=f"{on}, {names}")
        if status == OK and comp in self.live and (not names or b"logStatusError" in names):
            self.live[comp].log_errors = bool(on) and self.live[comp].logger

    def status_calls(self) -> None:
        rng = self.rng
        name, ctype = rng.choice((("fmi2GetStatus", c_int), ("fmi2GetRealStatus", c_double),
                                  ("fmi2GetIntegerStatus", c_int),
                                  ("fmi2GetBooleanStatus", c_int),
                                  ("fmi2GetStringStatus", c_char_p)))
        value = ctype()
        kind = rng.randrange(-1, 5)
        self.call(name, self.component(), kind, None if rng.random() < 0.1 else byref(value),
                  shown=str(kind))

    def unsupported(self) -> None:
        rng = self.rng
        comp = self.component()
        vr, val, order = (c_uint * 2)(0, 1), (c_double * 2)(), (c_int * 2)(1, 1)
        n = rng.randint(0, 2)
        name = rng.choice(("fmi2CancelStep", "fmi2SetRealInputDerivatives",
                           "fmi2GetRealOutputDerivatives", "fmi2GetDirectionalDerivative"))
        if name == "fmi2CancelStep":
            self.call(name, comp)
        elif name == "fmi2GetDirectionalDerivative":
            self.call(name, comp, vr, n, vr, n, val, (c_double * 2)(), shown=str(n))
        else:
            self.call(name, comp, vr, n, order, val, shown=str(n))

    def bad_component(self) -> None:
        """Any call on NULL, a garbage pointer or a freed instance: fmi2Error, no crash."""
        rng = self.rng
        freed = [i.pointer for i in self.instances if i.pointer not in self.live]
        comp = rng.choice(freed) if freed and rng.random() < 0.5 else self.garbage_pointer()
        state = c_void_p()
        choice = rng.randrange(6)
        if choice == 0:
            self.call("fmi2DoStep", comp, 0.0, self.f.step, 1, shown="")
        elif choice == 1:
            self.call("fmi2GetReal", comp, None, 0, None, shown="nvr=0")
        elif choice == 2:
            self.call("fmi2GetFMUstate", comp, byref(state), shown="")
        elif choice == 3:
            self.call("fmi2Reset", comp)
        elif choice == 4:
            self.call("fmi2SetDebugLogging", comp, 1, 0, None, shown="")
        else:
            self.f.tracer.write(f"fmi2FreeInstance({_hex(comp)})")
            self.f.lib.dll.fmi2FreeInstance(comp)
            self.f.tracer.write("\n")
            self.live.pop(comp or 0, None)

    def version(self) -> None:
        self.f.tracer.write("fmi2GetVersion(), fmi2GetTypesPlatform()\n")
        if self.f.lib.dll.fmi2GetVersion() != b"2.0" or \
                self.f.lib.dll.fmi2GetTypesPlatform() != b"default":
            raise Violation("fmi2GetVersion / fmi2GetTypesPlatform")

    # -- the end of a sequence --------------------------------------------------------------
    def cleanup(self) -> None:
        """Free the states (with the janitor: their instance may be gone) and the instances."""
        f = self.f
        for pointer in self.states:
            state = c_void_p(pointer)
            self.call("fmi2FreeFMUstate", f.janitor, byref(state), shown=_hex(pointer))
        for instance in list(self.live.values()):
            self.f.tracer.write(f"fmi2FreeInstance({_hex(instance.pointer)})\n")
            f.lib.dll.fmi2FreeInstance(instance.pointer)
        self.live.clear()


ACTIONS = [
    (lambda s: s.instantiate(), 3), (Sequence.free_instance, 2), (Sequence.setup, 3),
    (Sequence.enter_init, 3), (Sequence.exit_init, 3), (Sequence.initialize, 5),
    (lambda s: s.set_real(), 7), (lambda s: s.set_inputs(), 5), (lambda s: s.get_real(), 7),
    (Sequence.integers, 2), (Sequence.booleans_and_strings, 1), (Sequence.do_step, 10),
    (Sequence.run_steps, 5), (Sequence.get_state, 4), (Sequence.set_state, 3),
    (Sequence.free_state, 2), (Sequence.serialize, 3), (Sequence.deserialize, 5),
    (Sequence.reset, 2), (Sequence.terminate, 2), (Sequence.debug_logging, 1),
    (Sequence.status_calls, 2), (Sequence.unsupported, 1), (Sequence.bad_component, 1),
    (Sequence.version, 0.3),
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("spec")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--count", type=int, default=100)
    parser.add_argument("--trace", default=os.devnull)
    args = parser.parse_args(argv)
    with open(args.spec) as file:
        spec = json.load(file)
    tracer = Tracer(args.trace)
    tracer.restart(-1)
    fuzzer = Fuzzer(spec, tracer)
    start = time.perf_counter()
    summary = {"kind": spec["kind"], "first_seed": args.seed, "sequences": 0}
    for seed in range(args.seed, args.seed + args.count):
        tracer.restart(seed)
        try:
            Sequence(fuzzer, seed).run()
        except Violation as exc:
            summary.update(violation=str(exc), seed=seed)
            print(json.dumps(summary))
            return 3
        summary["sequences"] += 1
    summary.update(calls=fuzzer.calls, statuses=dict(zip(
        ("ok", "warning", "discard", "error", "fatal", "pending"), fuzzer.statuses)),
        seconds=round(time.perf_counter() - start, 3),
        errors=dict(sorted(fuzzer.errors.items(), key=lambda item: -item[1])))
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
