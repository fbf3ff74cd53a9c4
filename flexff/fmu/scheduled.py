"""An FMI 3.0 scheduled-execution FMU stepped like a co-simulation one: at each communication
point, the model partition of every periodic input clock that ticks there is activated, in the
order of the clocks' priorities (0 first).

This is a sequential scheduler: each partition runs to its end before the next starts, which
gives what a preemptive real-time scheduler gives when every task meets its deadline. Clocks
are input clocks of a constant interval (intervalDecimal, a whole number of communication
steps); an FMU with another kind (triggered, countdown, tunable, an output clock) is refused,
naming the clock. It is a stepper (fmu.stepper): the engine calls its step as a co-simulation
FMU's fmi3DoStep.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flexff.fmu.errors import InputError
from flexff.fmu.stepper import OK, Stepper

TICK_TOLERANCE = 1e-9  # relative: an interval this close to a whole number of steps is one


@dataclass(frozen=True)
class PeriodicClock:
    """An input clock that ticks every `interval` seconds from the start."""

    name: str
    value_reference: int
    interval: float
    priority: int


def periodic_clocks(fmu: Path) -> list[PeriodicClock]:
    """The clocks of the FMU at `fmu` in priority order, read from its modelDescription.xml
    (fmpy 0.3 reads neither a clock's interval nor its priority); InputError naming a clock this
    scheduler cannot run."""
    with zipfile.ZipFile(fmu) as archive:
        root = ET.fromstring(archive.read("modelDescription.xml"))
    clocks = []
    for v in root.iter("Clock"):
        name, kind = v.get("name", "?"), v.get("intervalVariability")
        interval = v.get("intervalDecimal")
        if v.get("causality") != "input" or kind != "constant" or interval is None:
            raise InputError(f"clock {name!r} is an {v.get('causality')} clock of {kind} "
                             f"interval: flexff schedules input clocks of a constant interval "
                             f"(intervalDecimal) only")
        clocks.append(PeriodicClock(name, int(v.get("valueReference", "-1")), float(interval),
                                    int(v.get("priority", "0"))))
    if not clocks:
        raise InputError("the FMU has no clock: a scheduled-execution FMU needs one")
    return sorted(clocks, key=lambda c: c.priority)


class ScheduledStepper(Stepper):
    """Communication steps of an initialized scheduled-execution FMU (fmpy
    FMU3ScheduledExecution)."""

    def __init__(self, fmu: Any, clocks: list[PeriodicClock], start: float) -> None:
        super().__init__(True, start)
        self.fmu, self.clocks, self.start = fmu, clocks, start
        self.points = 0
        self._every: list[int] | None = None  # each clock's interval in steps

    def _steps_per_tick(self, h: float) -> list[int]:
        every = []
        for clock in self.clocks:
            ratio = clock.interval / h
            if round(ratio) < 1 or abs(ratio - round(ratio)) > TICK_TOLERANCE * ratio:
                raise InputError(f"clock {clock.name!r} ticks every {clock.interval:g} s, not a "
                                 f"whole number of the run's {h:g} s steps")
            every.append(round(ratio))
        return every

    def step(self, h: float) -> int:
        """Activate the partitions of the clocks that tick at this point, then move on."""
        if self._every is None:
            self._every = self._steps_per_tick(h)
        for clock, every in zip(self.clocks, self._every, strict=True):
            if self.points % every == 0:
                self.fmu.activateModelPartition(clock.value_reference, self.time)
        self.points += 1
        self.time = self.start + self.points * h
        return OK
