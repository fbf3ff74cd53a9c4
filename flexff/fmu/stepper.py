"""A stepper: an FMU that flexff steps itself rather than by the FMU's own fmi*DoStep, a
model-exchange FMU with a solver (fmu.model_exchange) or a scheduled-execution FMU
(fmu.scheduled). Its step is a C callback (ctypes) with fmi2DoStep's or fmi3DoStep's signature,
so that the engine calls it through the FMU's plan as it calls a co-simulation FMU's own.
"""

from __future__ import annotations

from ctypes import CFUNCTYPE, POINTER, c_bool, c_double, c_int, c_void_p, cast
from typing import Any

STEP2 = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_int)
STEP3 = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_bool, POINTER(c_bool), POINTER(c_bool),
                  POINTER(c_bool), POINTER(c_double))
OK, ERROR, FATAL = 0, 3, 4  # fmi*Status: the engine fails a step above 1


class Stepper:
    """The callback around `step`; `error` keeps the exception of a failed step (it cannot
    cross the engine's C frames) and `time` is where the last step ended."""

    def __init__(self, fmi3: bool, start: float) -> None:
        self.time = start
        self.error: Exception | None = None
        self.callback = STEP3(self._step3) if fmi3 else STEP2(self._step2)

    @property
    def address(self) -> int:
        """The step callback's address, for the engine's plan."""
        address = cast(self.callback, c_void_p).value
        assert address is not None
        return address

    def step(self, h: float) -> int:
        """One communication step of length h; an fmi*Status."""
        raise NotImplementedError

    def _guarded(self, h: float) -> int:
        try:
            return self.step(h)
        except Exception as error:  # fmpy raises on an error status; CVODE on a failure
            self.error = error
            return FATAL

    def _step2(self, component: int | None, t: float, h: float, no_prior: int) -> int:
        return self._guarded(h)

    def _step3(self, component: int | None, t: float, h: float, no_prior: bool,
               event: Any, terminate: Any, early: Any, last: Any) -> int:
        status = self._guarded(h)
        last[0] = self.time
        return status
