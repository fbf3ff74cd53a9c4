"""Fixed-step co-simulation master: FMI 2.0 and 3.0 co-simulation FMUs loaded in-process (fmpy
loads the libraries and declares their functions), stepped by one compiled engine.

FMUs run in a fixed order, wired by cosim.wiring, Gauss-Seidel (default) or Jacobi. Float64
signals live in one array, the bus, which the FMUs' get and set calls write and read in place;
other types and converting connections go through fmpy's typed calls and cosim.wiring's rule.
The loop runs in compiled code (cosim/engine.py, cosim/c/engine.c), which checks every status
and every output's finiteness and times every step (cosim.timing). Python sets up, feeds the
sources and collects the record a chunk at a time, so memory does not grow with the run.

The step sequence of each algorithm and the engine: "The master algorithm"
(docs/explanation/master-algorithm.md).
"""

from __future__ import annotations

import dataclasses
import gc
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from ctypes import POINTER, byref, c_double, c_long, c_uint, c_void_p, cast
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from flexff.cosim.engine import (
    AFTER_RECORD,
    CALLS,
    FAILED,
    MAX_LISTED_OVERRUNS,
    NONFINITE,
    OK,
    OVERRUN,
    TYPED_HOOK,
    EngineFmuPlan,
    EngineRun,
    function_address,
    library,
    pointer,
    start_schedule,
)
from flexff.cosim.handover import ChunkBuffers, Handover, StepTimes, Worker
from flexff.cosim.interrupts import deferred
from flexff.cosim.isolation import IsolatedInstance
from flexff.cosim.recording import CHUNK_MIN_ROWS, Recording, chunk_rows
from flexff.cosim.sandbox import DEFAULT, Sandbox
from flexff.cosim.schema import ALGORITHMS, point_time
from flexff.cosim.timing import Pacing, StepTiming, StreamedTiming
from flexff.cosim.wiring import SOURCE, Link, Port, carried, wire
from flexff.fmu.errors import InputError, RunError
from flexff.fmu.importer import FmuError, FmuInfo, FmuInstance, read_fmu

PROGRESS_MIN_STEPS = 100_000  # runs this long show a progress bar (on a terminal)
PROGRESS_CHUNK = CHUNK_MIN_ROWS  # steps between progress bar updates (chunks hold whole ones)
PACED_CHUNK_S = 1.0  # a paced run hands its record over once a second (of its run time)


class Sink(Protocol):
    """Where a run's record goes, chunk by chunk, while it runs (Master.stream)."""

    def write(self, k0: int, time: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Points k0, k0 + 1, ... at times `time` [s], one array per recorded signal."""


@dataclass(frozen=True)
class Streamed:
    """What a run leaves beside the record it handed to its sink."""

    points: int  # points recorded
    wall_s: float  # seconds the engine stepped
    timing: StepTiming | StreamedTiming


class MemorySink:
    """A sink that keeps the record in memory (Master.run)."""

    def __init__(self) -> None:
        self.chunks: dict[str, list[np.ndarray]] = {}
        self.times: list[np.ndarray] = []

    def write(self, k0: int, time: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        self.times.append(time)
        for name, values in columns.items():
            self.chunks.setdefault(name, []).append(values)

    def recording(self, streamed: Streamed) -> Recording:
        return Recording(np.concatenate(self.times), {
            n: np.concatenate(c) for n, c in self.chunks.items()}, streamed.wall_s,
            streamed.timing)


class _NoBar:
    """The progress bar of a run that shows none (tqdm loads only for one that does)."""

    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def update(self, n: int) -> None:
        pass


def _progress_bar(steps: int, shown: bool) -> Any:
    if not shown:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=steps, unit="step", leave=False)


def _shifted(array: np.ndarray, rows: int) -> Any:
    """A pointer `rows` rows before `array`'s first: the engine indexes its buffers by the
    point k, so a chunk buffer whose first row holds point `rows` is given this way (only
    rows inside the buffer are ever touched)."""
    return cast(c_void_p(array.ctypes.data - rows * array.strides[0]), POINTER(c_double))


@dataclass(frozen=True)
class ResolvedFmu:
    """One FMU of a co-simulation: its instance name, its file and start values by name, its
    model description once read (a resolved scenario's, whose start values are checked), and
    the tolerance given to its own solver (None: not defined)."""

    name: str
    path: Path
    parameters: Mapping[str, Any] = field(default_factory=dict)
    info: FmuInfo | None = field(default=None, compare=False, repr=False)
    tolerance: float | None = None
    isolate: bool = False  # run it in its own process (cosim.isolation)
    solver: str | None = None  # run it as model exchange with this solver (fmu.model_exchange)
    allow_nonfinite: bool = False  # NaN and infinite outputs go on (else they stop the run)
    sandbox: Sandbox | None = DEFAULT  # an isolated FMU's sandbox (None: none)
    scheduled: bool = False  # run it through scheduled execution (fmu.scheduled)

    def described(self) -> FmuInfo:
        """The model description: the one carried, else read and the start values checked."""
        if self.info is not None:
            return self.info
        info = read_fmu(self.path)
        _check_parameters(self, info)
        return info


class CosimError(RunError):
    """An FMI call failed during a co-simulation (the message carries the FMU's log)."""


class NonFinite(CosimError):
    """An FMU gave a NaN or infinite output where it does not allow them."""


class _Plan:
    """How one FMU reads its inputs from and writes its outputs to the bus (numpy arrays the
    engine's EngineFmuPlan points into)."""

    def __init__(self, instance: FmuInstance | IsolatedInstance, fmu: ResolvedFmu,
                 links: Sequence[Link],
                 bus_index: Mapping[str, int], bus: np.ndarray, out_offset: int,
                 read_before: bool, read_after: bool) -> None:
        info = instance.info
        self.instance, self.name, self.parameters = instance, fmu.name, dict(fmu.parameters)
        self.tolerance, self.finite = fmu.tolerance, not fmu.allow_nonfinite
        floats = [k for k in links if k.on_bus]
        self.typed_inputs = [k for k in links if not k.on_bus]  # set by Python (_set_typed)
        self.inputs = tuple(k.input for k in floats)
        self.outputs = tuple(n for n in info.outputs if info.variables[n].kind == "float64")
        self.typed_outputs = [n for n in info.outputs if info.variables[n].kind != "float64"]
        self.out_offset, self.read_before, self.read_after = out_offset, read_before, read_after
        gather = np.array([bus_index[k.from_name] for k in floats], dtype=np.int64)
        affine = any(k.affine for k in floats)
        contiguous = gather.size == 0 or np.array_equal(
            gather, np.arange(gather[0], gather[0] + gather.size))
        self.gather = self.gain = self.offset = None
        if contiguous and not affine:
            start = int(gather[0]) if gather.size else 0
            self.in_values = bus[start:start + gather.size]
        else:
            self.in_values, self.gather = np.zeros(gather.size), gather
            if affine:
                self.gain = np.array([k.gain for k in floats])
                self.offset = np.array([k.offset for k in floats])
        self.in_vr = np.array([info.variables[n].value_reference for n in self.inputs],
                              dtype=np.uint32)
        self.out_vr = np.array([info.variables[n].value_reference for n in self.outputs],
                               dtype=np.uint32)
        self.out_values = bus[out_offset:out_offset + len(self.outputs)]

    def gathered(self, bus: np.ndarray) -> np.ndarray:
        """The float inputs' values from the bus, scaled and shifted (as the engine does)."""
        if self.gather is None:
            return self.in_values
        values = bus[self.gather]
        return values if self.gain is None else values * self.gain + self.offset

    def calls(self) -> tuple[bool, int | None, int, int, int]:
        """(fmi3, component, set, get, step): the FMU's own functions, or an isolated FMU's
        proxy (cosim.isolation)."""
        if isinstance(self.instance, IsolatedInstance):
            return self.instance.calls()
        dll = self.instance.fmu.dll
        fmi3 = self.instance.info.fmi_version == "3.0"
        names = (("fmi3SetFloat64", "fmi3GetFloat64", "fmi3DoStep") if fmi3 else
                 ("fmi2SetReal", "fmi2GetReal", "fmi2DoStep"))
        set_, get = function_address(dll, names[0]), function_address(dll, names[1])
        stepper = self.instance.stepper  # model exchange: the solver's step
        step = stepper.address if stepper is not None else function_address(dll, names[2])
        return fmi3, self.instance.component.value, set_, get, step

    def engine_plan(self) -> EngineFmuPlan:
        task = self.instance.network_task()  # its overruns count as the engine's own
        counter = task[1] if task else 0
        return EngineFmuPlan(
            *self.calls(),
            len(self.inputs), pointer(self.in_vr, c_uint), pointer(self.gather, c_long),
            pointer(self.gain), pointer(self.offset), pointer(self.in_values),
            len(self.outputs), pointer(self.out_vr, c_uint), pointer(self.out_values),
            self.read_before, self.read_after, bool(self.typed_inputs),
            bool(self.typed_outputs), counter or None,
            c_long.from_address(counter).value if counter else 0, self.finite)

    def fail(self, what: str) -> CosimError:
        return CosimError(str(self.instance.fail(what)))

    def check_finite(self, names: Sequence[str], values: Sequence[Any], time: float) -> None:
        """NonFinite for the first NaN or infinite float among an FMU's outputs `names` just
        read (their `values`) at `time`, unless the FMU allows them."""
        if not self.finite:
            return
        for name, value in zip(names, values):
            if isinstance(value, float) and not math.isfinite(value):
                raise NonFinite(f"{self.name}: output {name!r} is {value} at t = {time:.9g} s: "
                                f"a non-finite value stops the run (set allow_nonfinite = true "
                                f"in [fmu.{self.name}], or in [run] for every FMU, where it "
                                f"is meant)")


class Master:
    """Loaded FMUs wired together, ready for one run; use it as a context manager.

    `sources` names the external signals (the reference, constants) given to `run`; `links`
    is the wiring (cosim.wiring.wire; default: every input by name); `start` the time of
    point 0; `step_timeout` (s) bounds every call of an isolated FMU; `log`, where given, takes
    every message of the FMUs loaded in this process, one line each (cosim.fmu_log).
    """

    def __init__(self, fmus: Sequence[ResolvedFmu], sources: Sequence[str], step: float,
                 links: Sequence[Link] | None = None, algorithm: str = "gauss-seidel",
                 start: float = 0.0, step_timeout: float | None = None,
                 log: Callable[[str], None] | None = None) -> None:
        if not step > 0:
            raise InputError(f"step must be positive, got {step}")
        if algorithm not in ALGORITHMS:
            raise InputError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")
        if not math.isfinite(start):
            raise InputError(f"start must be finite, got {start}")
        self.step, self.algorithm, self.start = float(step), algorithm, float(start)
        self.sources = tuple(sources)
        self.fmus = list(fmus)
        self._plans: list[_Plan] = []
        self._instances: list[FmuInstance | IsolatedInstance] = []
        infos = [s.described() for s in fmus]
        if links is None:
            links = wire([Port(s.name, i) for s, i in zip(fmus, infos)], self.sources,
                         algorithm=algorithm)
        self.links = tuple(links)
        try:
            for fmu, info in zip(fmus, infos):
                self._instances.append(
                    IsolatedInstance(info, fmu.name, step_timeout, fmu.solver, fmu.sandbox,
                                     fmu.scheduled, log) if fmu.isolate
                    else FmuInstance(info, fmu.name, fmu.solver, scheduled=fmu.scheduled,
                                     log=log))
            self._layout(infos)
        except BaseException:
            self.close()
            raise
        self._ran = False

    # -- layout -------------------------------------------------------------------------
    def _layout(self, infos: Sequence[FmuInfo]) -> None:
        names = list(self.sources)
        offsets = {}
        for fmu, info in zip(self.fmus, infos):
            offsets[fmu.name] = len(names)
            names += [f"{fmu.name}.{n}" for n in info.outputs
                      if info.variables[n].kind == "float64"]
        self.signals = tuple(names)
        self._index = index = {n: i for i, n in enumerate(names)}
        self._bus = np.zeros(len(names))
        self._typed: dict[str, Any] = {}
        jacobi = self.algorithm == "jacobi"
        feeds_later = {s.name: False for s in self.fmus}
        feeds_back = dict(feeds_later)
        for link in self.links:
            if link.producer != SOURCE:
                (feeds_back if link.feedback else feeds_later)[link.producer] = True
        for fmu, instance in zip(self.fmus, self._instances):
            links = [k for k in self.links if k.consumer == fmu.name]
            self._plans.append(_Plan(
                instance, fmu, links, index, self._bus, offsets[fmu.name],
                read_before=not jacobi and (feeds_later[fmu.name] or not feeds_back[fmu.name]),
                read_after=jacobi or feeds_back[fmu.name]))
        self.typed_signals = tuple(f"{p.name}.{n}" for p in self._plans for n in p.typed_outputs)
        self._typed_index = frozenset(self.typed_signals)
        self._own_names: dict[str, list[str]] = {}  # an output's own name -> its full names
        for signal in (*self.signals, *self.typed_signals):
            self._own_names.setdefault(signal.partition(".")[2], []).append(signal)

    def layout(self) -> dict[str, Any]:
        """The bus layout and every FMU's call plan, as plain data (for the C floor, whose plan
        holds FMI 2.0 FMUs with float inputs and outputs, no gains, Gauss-Seidel)."""
        for p in self._plans:
            if (p.instance.info.fmi_version != "2.0" or p.gain is not None or p.typed_inputs
                    or p.typed_outputs or self.algorithm != "gauss-seidel" or self.start
                    or p.tolerance is not None or isinstance(p.instance, IsolatedInstance)
                    or p.instance.model_exchange):
                raise InputError(f"the C floor runs FMI 2.0 FMUs with Real signals and no gains "
                                 f"under Gauss-Seidel, from t = 0 with no tolerance, in its "
                                 f"process, co-simulated; {p.name} does not fit")
        index = {n: i for i, n in enumerate(self.signals)}
        by_target = {(k.consumer, k.input): k.from_name for k in self.links}
        return {
            "step": self.step, "signals": list(self.signals), "n_sources": len(self.sources),
            "fmus": [{
                "name": p.name, "library": str(p.instance.library),
                "guid": p.instance.info.token,
                "parameters": [(p.instance.info.variables[n].value_reference,
                                p.instance.info.variables[n].type, v)
                               for n, v in p.parameters.items()],
                "inputs": [(p.instance.info.variables[n].value_reference,
                            index[by_target[(p.name, n)]]) for n in p.inputs],
                "outputs": [p.instance.info.variables[n].value_reference for n in p.outputs],
                "output_offset": p.out_offset,
                "read_before": p.read_before, "read_after": p.read_after,
            } for p in self._plans]}

    # -- running ------------------------------------------------------------------------
    def run(self, sources: Mapping[str, np.ndarray | float], steps: int,
            record: Sequence[str] | None = None, progress: bool | None = None,
            pacing: Pacing | None = None) -> Recording:
        """Run `steps` steps from the start; return the recorded signals at the steps + 1
        points, held in memory (`stream` hands them to a sink instead).

        `sources` gives every source signal as a constant or as steps + 1 samples; `record`
        names the signals to keep (default: all; `fmu.output`, a source, or an output's own
        name where only one FMU has it); `progress` shows a tqdm bar (default: on a
        terminal, for runs of at least PROGRESS_MIN_STEPS steps); `pacing` paces the steps to
        the wall clock. The recording's `timing` holds every step's execution time; a paced
        run stopped by its overruns holds the points up to the last step it made.
        """
        sink = MemorySink()
        streamed = self.stream(sources, steps, sink, record, progress, pacing)
        return sink.recording(streamed)

    def stream(self, sources: Mapping[str, np.ndarray | float], steps: int, sink: Sink,
               record: Sequence[str] | None = None, progress: bool | None = None,
               pacing: Pacing | None = None, keep_timing: bool = True,
               worker: Worker | None = None) -> Streamed:
        """Run as `run` does, handing the record to `sink` chunk by chunk while it runs
        (cosim.recording.chunk_rows points a chunk; a paced run one every PACED_CHUNK_S
        seconds), so that memory stays flat in the run's length. Without `keep_timing` the
        steps' execution times (and, paced, their lateness) are counted in histograms and a
        bounded trace (cosim.timing.StreamedTiming), not kept one by one. With a `worker`,
        each chunk is split, written and counted in its thread while the next one runs
        (cosim.handover). A run that fails hands over the points before the failure first."""
        if self._ran:
            raise RuntimeError("a Master runs once; load the FMUs again for another run")
        self._ran = True
        source_columns = self._source_columns(sources, steps)
        everything = (*self.signals, *self.typed_signals)
        record = list(everything if record is None else record)
        resolved = [self.resolve(n) for n in record]
        floats = [(j, self._index[q]) for j, q in enumerate(resolved) if q in self._index]
        typed = [(j, q) for j, q in enumerate(resolved) if q not in self._index]
        columns = np.array([i for _, i in floats], dtype=np.int64)
        full = len(floats) == len(resolved) and np.array_equal(
            columns, np.arange(len(self.signals)))
        rows = min(steps + 1, chunk_rows(1 + len(record)) if pacing is None else
                   PROGRESS_CHUNK * max(1, round(PACED_CHUNK_S / self.step / PROGRESS_CHUNK)))
        source_rows = np.empty((rows, len(self.sources)))
        sets = [ChunkBuffers.allocate(rows, len(floats), len(typed),
                                      None if keep_timing else len(self._plans),
                                      touch=pacing is not None)
                for _ in range(1 if worker is None else 2)]
        needed = {q for _, q in typed} | {k.from_name for k in self.links if k.kind != "float64"}
        for p in self._plans:  # typed outputs cost a call each: read only those in use
            p.typed_outputs = [n for n in p.typed_outputs if f"{p.name}.{n}" in needed]
        for p in self._plans:
            try:
                p.instance.initialize(p.parameters, self.start, self.time(steps),
                                      p.tolerance)
            except FmuError as error:
                raise CosimError(str(error)) from None
            if p.read_after:
                self._read(p, "after initialization")
        if self.algorithm == "jacobi":
            _fill_source_rows(source_rows, source_columns, 0)
            self._propagate_initial_values(source_rows[0])
        hook = _TypedHook(self, [(column, q) for column, (_, q) in zip(sets[0].typed, typed)])
        run = self._engine_run(source_rows, sets, None if full else columns, hook, steps,
                               pacing)
        streamed_timing = None if keep_timing else StreamedTiming.counting(
            self.step, tuple(p.name for p in self._plans), steps, pacing)
        float_columns = {j: c for c, (j, _) in enumerate(floats)}
        typed_columns = {j: c for c, (j, _) in enumerate(typed)}

        def window(base: int, buffers: ChunkBuffers) -> None:
            """Point the engine at `buffers`, so that point k lands in (and its sources come
            from, filled before) row k - base."""
            hook.base = base
            hook.columns = [(column, q) for column, (_, q) in zip(buffers.typed, typed)]
            run.sources = _shifted(source_rows, base)
            run.record = _shifted(buffers.record, base)
            if buffers.times is not None:
                run.tet, run.fmu_tet, run.lateness = (_shifted(a, base) for a in buffers.times)

        def deliver(buffers: ChunkBuffers, base: int, end: int) -> None:
            """Give the sink points base .. end - 1 (and count their steps' times)."""
            n = end - base
            chunk = {name: buffers.record[:n, float_columns[j]].copy() if j in float_columns
                     else _typed_array(buffers.typed[typed_columns[j]][:n])
                     for j, name in enumerate(record)}
            sink.write(base, self.time(np.arange(base, end)), chunk)
            if streamed_timing is not None and buffers.times is not None:
                made = max(0, min(end, steps) - base)
                streamed_timing.add(base, *(a[:made] for a in buffers.times))

        handover = Handover(sets, deliver, worker)

        def hand(base: int, end: int) -> None:
            """Hand points base .. end - 1 over, and go on at point `end` (its sources filled
            before the handover wakes its worker)."""
            if end > base:
                _fill_source_rows(source_rows, source_columns, end)
                window(end, handover.hand(base, end))

        if progress is None:
            progress = sys.stderr.isatty() and steps >= PROGRESS_MIN_STEPS
        engine = library()
        status, end, base, wall = OK, steps + 1, 0, 0.0
        _fill_source_rows(source_rows, source_columns, base)
        window(base, handover.current)
        gc_was_enabled = gc.isenabled()
        gc.disable()  # no collection pauses inside the loop
        recorded = 0  # the points recorded so far
        with deferred() as interrupted:  # Ctrl-C and SIGTERM raised between engine calls
            try:
                with _progress_bar(steps, progress) as bar:
                    if pacing is not None:
                        start_schedule(run)
                    for k0 in range(0, steps + 1, PROGRESS_CHUNK):
                        k1 = min(k0 + PROGRESS_CHUNK, steps + 1)
                        start = time.perf_counter()
                        status = engine.engine_run(byref(run), k0, k1)
                        wall += time.perf_counter() - start
                        if status != OK:
                            break
                        recorded = k1
                        bar.update(min(k1, steps) - k0)
                        if k1 - base == rows or k1 == steps + 1:
                            hand(base, k1)
                            base = k1
                        interrupted()
                stopped_at = run.failed_k if status == OVERRUN else None
                row = (stopped_at or 0) - base  # the stopped step's row in the chunk buffers
                made_times = handover.current.times
                stopped_step = (float(made_times.tet[row]), float(made_times.lateness[row])) \
                    if stopped_at is not None and made_times is not None else (0.0, 0.0)
                if status == FAILED:  # points before failed_k were recorded, failed_k if its
                    # step failed after recording
                    hand(base, max(base, run.failed_k + (run.failed_call in AFTER_RECORD)))
                elif stopped_at is not None:
                    end = stopped_at + 1  # points 0 .. stopped_at were recorded, step made
                    hand(base, end)
            except KeyboardInterrupt:  # the points so far, handed over before it is raised on
                hand(base, max(base, recorded))
                raise
            finally:
                handover.wait()
                if gc_was_enabled:
                    gc.enable()
        handover.check()
        if status == FAILED and run.failed_call in NONFINITE:
            p = self._plans[run.failed_fmu]
            k = run.failed_k + (run.failed_call in AFTER_RECORD)  # the point of the values
            p.check_finite(p.outputs, p.out_values.tolist(), self.time(k))
        if status == FAILED:
            raise hook.error or self._plans[run.failed_fmu].fail(
                f"{CALLS[run.failed_call]} at t = {self.time(run.failed_k):.9g} s")
        network = {p.name: times for p in self._plans if (times := p.instance.network_times())}
        listed = tuple(run.first_overruns[:min(run.overruns, MAX_LISTED_OVERRUNS)])
        if streamed_timing is not None:
            return Streamed(end, wall, dataclasses.replace(
                streamed_timing, overruns=run.overruns, task_overruns=run.task_overruns,
                first_overruns=listed, stopped_at=stopped_at, network_calls=network,
                stopped_step=stopped_step))
        made = end if stopped_at is not None else steps  # the steps the engine made
        tet, fmu_tet, lateness = (a[:made] for a in self._times)
        timing = StepTiming(self.step, tuple(p.name for p in self._plans), tet, fmu_tet,
                            lateness, pacing, run.overruns, run.task_overruns, listed,
                            stopped_at, network_calls=network)
        return Streamed(end, wall, timing)

    def time(self, k: Any) -> Any:
        """The time of point(s) k (cosim.schema.point_time)."""
        return point_time(self.start, self.step, k)

    def _engine_run(self, source_rows: np.ndarray, sets: Sequence[ChunkBuffers],
                    columns: np.ndarray | None, hook: _TypedHook, steps: int,
                    pacing: Pacing | None) -> EngineRun:
        """The engine's plan and buffers, allocated before the loop: the chunk buffers `sets`
        and the step times of every step, unless the chunk buffers count them."""
        self._plan_structs = (EngineFmuPlan * len(self._plans))(
            *(p.engine_plan() for p in self._plans))
        first = sets[0]
        self._times = StepTimes.zeros(steps, len(self._plans)) if first.times is None \
            else first.times
        if pacing is not None:  # touched now, so the paced loop takes no page fault in them
            for array in (source_rows, *self._times):
                array.fill(0.0)  # (cosim.realtime locks pages as they are touched)
        self._arrays = (source_rows, sets, columns)  # the engine's buffers live as long
        self._hook = TYPED_HOOK(hook) if hook.needed else TYPED_HOOK()
        return EngineRun(
            step=self.step, start_time=self.start, steps=steps, n_fmus=len(self._plans),
            fmus=self._plan_structs,
            bus=pointer(self._bus), n_bus=self._bus.size, n_sources=len(self.sources),
            sources=pointer(source_rows), record=pointer(first.record),
            columns=pointer(columns, c_long), n_columns=first.record.shape[1], typed=self._hook,
            typed_record=bool(hook.columns),
            tet=pointer(self._times.tet), fmu_tet=pointer(self._times.fmu_tet),
            lateness=pointer(self._times.lateness), paced=pacing is not None,
            period=self.step / pacing.rt_factor if pacing else self.step,
            max_overruns=pacing.max_overruns if pacing else 0,
            grace_steps=math.ceil(pacing.grace / self.step - 1e-9) if pacing else 0)

    def resolve(self, name: str) -> str:
        """The full name of a signal: `fmu.output`, a source, or a unique output's own name."""
        if name in self._index or name in self._typed_index:
            return name
        matches = self._own_names.get(name, ())
        if len(matches) == 1:
            return matches[0]
        if matches:
            raise InputError(f"signal {name!r} is ambiguous: {', '.join(matches)}")
        raise InputError(f"cannot record unknown signal {name!r}; known: "
                         f"{', '.join((*self.signals, *self.typed_signals))}")

    def _source_columns(self, values: Mapping[str, np.ndarray | float], steps: int
                        ) -> list[np.ndarray]:
        """Every source's values in the bus's order, checked before the run (steps + 1 finite
        samples, or a finite constant) and not copied (a float64 array is used as given): the
        engine's rows are filled from them chunk by chunk (_fill_source_rows)."""
        sources = set(self.sources)
        missing = [n for n in self.sources if n not in values]
        extra = [n for n in values if n not in sources]
        if missing or extra:
            raise ValueError(f"source values: missing {missing}, unexpected {extra}")
        columns = []
        for name in self.sources:
            column = np.asarray(values[name], dtype=float)
            if column.ndim and column.shape != (steps + 1,):
                raise ValueError(f"source {name!r} has {column.shape} samples, the run needs "
                                 f"({steps + 1},) (or a constant)")
            if not np.isfinite(column).all():
                raise ValueError(f"source {name!r} has non-finite values")
            columns.append(column)
        return columns

    def _propagate_initial_values(self, sources: np.ndarray) -> None:
        """Jacobi: carry the initial values through every connection before the first step
        (inputs set, outputs read, once per FMU: through any chain), as libcosim does."""
        self._bus[:len(self.sources)] = sources
        for _ in self._plans:
            for p in self._plans:
                try:
                    p.instance.set(dict(zip(p.inputs, p.gathered(self._bus).tolist())))
                except FmuError:
                    raise p.fail("setting its inputs before the first step") from None
                self._set_typed(p, "before the first step")
            for p in self._plans:
                self._read(p, "before the first step")

    def _read(self, p: _Plan, when: str) -> None:
        """Read an FMU's outputs of every type (those of point 0) into the bus and the typed
        table."""
        try:
            values = p.instance.get(p.outputs)
        except FmuError:
            raise p.fail(f"getting its outputs {when}") from None
        p.check_finite(p.outputs, values, self.start)
        p.out_values[:] = values
        self._read_typed(p, when, 0)

    def _read_typed(self, p: _Plan, when: str, k: int) -> None:
        if p.typed_outputs:
            try:
                values = p.instance.get(p.typed_outputs)
            except FmuError:
                raise p.fail(f"getting its outputs {when}") from None
            p.check_finite(p.typed_outputs, values, self.time(k))
            self._typed.update((f"{p.name}.{n}", v) for n, v in zip(p.typed_outputs, values))

    def _set_typed(self, p: _Plan, when: str) -> None:
        if p.typed_inputs:
            values = {k.input: self._carried(k, when) for k in p.typed_inputs}
            try:
                p.instance.set(values)
            except FmuError:
                raise p.fail(f"setting its inputs {when}") from None

    def _carried(self, link: Link, when: str) -> Any:
        """What a link off the float64 bus gives its input now (cosim.wiring.carried): its
        producer's value from the bus (float64) or the typed table, converted."""
        value = (self._bus[self._index[link.from_name]] if link.kind == "float64"
                 else self._typed[link.from_name])
        try:
            return carried(link, value)
        except OverflowError as error:
            raise CosimError(f"{link} {when}: {error}") from None

    def scratch(self) -> list[Path]:
        """The temporary folders of the loaded FMUs (each removed when it is closed)."""
        return [s for i in self._instances if (s := i.scratch) is not None]

    def close(self) -> None:
        """Terminate and free every FMU (safe to call twice)."""
        while self._instances:
            self._instances.pop().close()

    def __enter__(self) -> Master:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _TypedHook:
    """The engine's hook for values of other types than float64: called where an FMU with
    such inputs sets them (phase 0) or reads such outputs (phase 1), and to record them at a
    point (phase 2). An exception is kept in `error` (it cannot cross the C frames)."""

    def __init__(self, master: Master, columns: list[tuple[np.ndarray, str]]) -> None:
        self.master, self.columns = master, columns
        self.error: Exception | None = None
        self.base = 0  # the point in the columns' first row
        self.needed = bool(columns) or any(p.typed_inputs or p.typed_outputs
                                           for p in master._plans)

    def __call__(self, fmu: int, phase: int, k: int) -> int:
        try:
            when = f"at t = {self.master.time(k):.9g} s"
            if phase == 0:
                self.master._set_typed(self.master._plans[fmu], when)
            elif phase == 1:
                self.master._read_typed(self.master._plans[fmu], when, k)
            else:
                for column, name in self.columns:
                    column[k - self.base] = self.master._typed[name]
        except Exception as error:
            self.error = error
            return 1
        return 0


def _check_parameters(fmu: ResolvedFmu, info: FmuInfo) -> None:
    """Start values may be given to parameters and inputs the FMU has."""
    settable = [n for n, v in info.variables.items() if v.settable]
    for name in fmu.parameters:
        if name not in settable:
            raise InputError(f"{fmu.name}: unknown parameter {name!r} (known: "
                             f"{', '.join(settable)})")


def _fill_source_rows(rows: np.ndarray, columns: Sequence[np.ndarray], base: int) -> None:
    """The sources of points base, base + 1, ... into the engine's rows (as many as the rows
    hold and the run has; a constant fills its column)."""
    for j, column in enumerate(columns):
        values = column if column.ndim == 0 else column[base:base + rows.shape[0]]
        rows[:values.size if column.ndim else rows.shape[0], j] = values


def _typed_array(values: np.ndarray) -> np.ndarray:
    """A recorded column of another type as a plain numpy array (binary as hex strings)."""
    if not values.size:  # a run that failed at its first point
        return np.array([])
    first = values[0]
    if isinstance(first, bytes):
        return np.array([v.hex() for v in values])
    if isinstance(first, str):
        return np.array(list(values), dtype=str)
    return np.array(list(values))
