"""Handing a streamed run's filled chunk over, so that a paced loop's thread only swaps buffers
between two chunks.

The master fills one set of chunk buffers (the record, the columns of other types and, counted
per chunk, the steps' times) while the set filled before is delivered: split into the sink's
columns, written, its times counted. Paced, the delivery runs in a Worker's thread while the
engine steps without the GIL, and the loop's thread takes the other set; unpaced, it runs at
once in the loop's own thread, on the one set.

Measured on the hardware loop paced at 1 kHz on one core (flexff run --realtime --cpu 1,
10 s): delivering in the loop's thread took it 0.9-1.8 ms between two chunks (counting the
times in histograms most of it), so the first step of a second started late and overran in
four of five runs; with the delivery in the Worker's thread, 0.2-0.4 ms, and none of five.
The next chunk's sources are filled before the Worker is woken: filled after, while the
Worker ran on the other core, they took 130-390 µs instead of 60.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class Worker:
    """A thread that runs the calls given to it, in order. It keeps the scheduling and the
    CPUs of the thread that creates it: create it before a paced loop's thread takes
    SCHED_FIFO and one core (cosim.realtime), or it would compete with the loop there."""

    def __init__(self, name: str = "flexff-record") -> None:
        self.calls: queue.SimpleQueue[Callable[[], None] | None] = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._work, name=name, daemon=True)
        self.thread.start()

    def submit(self, call: Callable[[], None]) -> None:
        self.calls.put(call)

    def _work(self) -> None:
        while (call := self.calls.get()) is not None:
            call()

    def join(self) -> None:
        """Run what was submitted, then end the thread."""
        self.calls.put(None)
        self.thread.join()


class StepTimes(NamedTuple):
    """The steps' execution times (steps), each FMU's share (steps x FMUs) and, paced, how
    late each step started (steps) [s]."""

    tet: np.ndarray
    fmu_tet: np.ndarray
    lateness: np.ndarray

    @classmethod
    def zeros(cls, steps: int, fmus: int) -> StepTimes:
        return cls(np.zeros(steps), np.zeros((steps, fmus)), np.zeros(steps))


@dataclass
class ChunkBuffers:
    """One chunk's engine buffers: the recorded float64 signals (rows x signals), a column per
    recorded signal of another type, and the steps' times where they are counted per chunk
    (None where the run keeps them whole)."""

    record: np.ndarray
    typed: list[np.ndarray]
    times: StepTimes | None

    @classmethod
    def allocate(cls, rows: int, signals: int, typed: int, fmus: int | None,
                 touch: bool) -> ChunkBuffers:
        """Buffers of `rows` rows, with step times for `fmus` FMUs (None: none); `touch`
        writes every page now, so that a paced loop takes no page fault in them."""
        buffers = cls(np.empty((rows, signals)), [np.empty(rows, dtype=object)
                                                  for _ in range(typed)],
                      None if fmus is None else StepTimes.zeros(rows, fmus))
        if touch:
            for array in (buffers.record, *(buffers.times or ())):
                array.fill(0.0)
        return buffers


Deliver = Callable[[ChunkBuffers, int, int], None]  # (buffers, first point, end point)


class Handover:
    """Delivers filled chunk buffers (`deliver`) in `worker`'s thread, each set given back to
    be filled again once delivered, or, without a worker, at once on the one set. A delivery
    that raises stops the later ones; `check` raises its error."""

    def __init__(self, sets: Sequence[ChunkBuffers], deliver: Deliver,
                 worker: Worker | None) -> None:
        if len(sets) != (1 if worker is None else 2):
            raise ValueError("a handover fills one set of buffers, or two with a worker")
        self.deliver, self.worker = deliver, worker
        self.current = sets[0]
        self.error: BaseException | None = None
        self.free: queue.SimpleQueue[ChunkBuffers] = queue.SimpleQueue()
        for buffers in sets[1:]:
            self.free.put(buffers)

    def hand(self, base: int, end: int) -> ChunkBuffers:
        """Deliver points base .. end - 1 of the current buffers (their rows 0 .. end - base
        - 1); return the buffers to fill next, waiting while both sets are being delivered."""
        if self.worker is None:
            self.deliver(self.current, base, end)
            return self.current
        filled = self.current
        self.worker.submit(lambda: self._deliver(filled, base, end))
        self.current = self.free.get()
        return self.current

    def _deliver(self, buffers: ChunkBuffers, base: int, end: int) -> None:
        try:
            if self.error is None:
                self.deliver(buffers, base, end)
        except BaseException as error:  # raised in the loop's thread by check()
            self.error = error
        finally:
            self.free.put(buffers)

    def wait(self) -> None:
        """Return once every chunk handed over is delivered."""
        if self.worker is not None:
            done = threading.Event()
            self.worker.submit(done.set)
            done.wait()

    def check(self) -> None:
        """Raise what a delivery met."""
        if self.error is not None:
            raise self.error
