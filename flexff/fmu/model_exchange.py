"""A model-exchange FMU (FMI 2.0 or 3.0) stepped like a co-simulation one: integrated with
SUNDIALS CVODE (the build FMPy ships, fmpy.sundials) between communication points, with time,
state and step events handled as the standard says and as FMPy's simulate_fmu does.

After initialization (`begin`): the event iteration (fmi2NewDiscreteStates /
fmi3UpdateDiscreteStates until no new discrete states are needed), continuous-time mode, and
the solver from the start time. Each communication step (`step`) integrates to the next point,
start + (k + 1) * step, stopping at the next time event and at every state event CVODE's root
finding reports; after each solver step the time is set and fmi*CompletedIntegratorStep asks
for a step event; at any event the FMU enters event mode, iterates its discrete states,
returns to continuous-time mode, and the solver restarts from there. Inputs are held over the
step (set before it, as for a co-simulation FMU).

It is a stepper (fmu.stepper): the engine calls its step as a co-simulation FMU's fmi*DoStep.
"""

from __future__ import annotations

import math
from typing import Any

from flexff.fmu.stepper import ERROR, OK, Stepper

SOLVERS = ("cvode",)
DEFAULT_TOLERANCE = 1e-5  # CVODE's relative tolerance where neither the run nor the FMU gives one
MAX_STEP_FRACTION = 50  # the solver's largest step: the run's length / this (as FMPy)


class _NoInput:
    """fmpy's CVodeSolver applies inputs at root-finding times; the master holds them."""

    def apply(self, *args: Any, **kwargs: Any) -> None:
        pass


def _close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)  # fmpy.simulation's isclose


class ModelExchangeStepper(Stepper):
    """Communication steps of an initialized model-exchange FMU (fmpy FMU2Model / FMU3Model)."""

    def __init__(self, fmu: Any, fmi3: bool, start: float, stop: float | None,
                 tolerance: float | None, n_states: int, n_indicators: int,
                 completed_step_needed: bool, step: float | None = None) -> None:
        from fmpy.sundials import CVodeSolver

        super().__init__(fmi3, start)
        self.fmu, self.fmi3, self.start = fmu, fmi3, start
        self.completed_step_needed = completed_step_needed
        self.points = 0
        self.next_event: float | None = None
        self._iterate()
        fmu.enterContinuousTimeMode()
        length = (stop - start) if stop is not None and stop > start else None
        self.solver = CVodeSolver(
            nx=n_states, nz=n_indicators, get_x=fmu.getContinuousStates,
            set_x=fmu.setContinuousStates,
            get_dx=fmu.getContinuousStateDerivatives if fmi3 else fmu.getDerivatives,
            get_z=fmu.getEventIndicators, get_nominals=fmu.getNominalsOfContinuousStates,
            set_time=fmu.setTime, input=_NoInput(), startTime=start,
            maxStep=length / MAX_STEP_FRACTION if length else float("inf"),
            relativeTolerance=tolerance or DEFAULT_TOLERANCE)

    def _iterate(self) -> bool:
        """The event iteration; whether the FMU asked to terminate. Keeps its next time
        event."""
        needed, terminate = True, False
        while needed and not terminate:
            result = (self.fmu.updateDiscreteStates() if self.fmi3
                      else self.fmu.newDiscreteStates())
            needed, terminate = bool(result[0]), bool(result[1])
            self.next_event = float(result[5]) if result[4] else None
        return terminate

    def step(self, h: float) -> int:
        """Integrate to the next communication point, start + (k + 1) * h."""
        target = self.start + (self.points + 1) * h
        while not _close(self.time, target) and self.time < target:
            until = target
            if self.next_event is not None and self.next_event < until \
                    and not _close(self.next_event, until):
                until = self.next_event
            time_event = self.next_event is not None and _close(until, self.next_event)
            state_event, _, self.time = self.solver.step(self.time, until)
            self.fmu.setTime(self.time)
            step_event = terminate = False
            if self.completed_step_needed:
                step_event, terminate = (bool(v) for v in self.fmu.completedIntegratorStep())
                if terminate:
                    return ERROR
            if time_event or state_event or step_event:
                self.fmu.enterEventMode()
                if self._iterate():
                    return ERROR
                self.fmu.enterContinuousTimeMode()
                self.solver.reset(self.time)
        self.points += 1
        return OK
