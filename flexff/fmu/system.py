"""Plain description of a dynamic system that fmu/ turns into an FMI 2.0 co-simulation FMU.

Following do-mpc / acados, a model is first described as data (named variables with units and
CasADi functions), then generated into C, then run. Nothing here knows about any particular
machine: the plant and the controllers fill these objects in.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:  # annotations only: describing signals needs neither CasADi nor onnx
    import casadi as ca

    from flexff.fmu.network import Network


@dataclass(frozen=True)
class Variable:
    """A named real scalar of the FMU (state, input or output)."""

    name: str
    unit: str = ""
    description: str = ""
    start: float = 0.0


@dataclass(frozen=True)
class Parameter(Variable):
    """A real parameter; `positive` parameters are rejected at initialization if <= 0. Tunable
    (settable while stepping) unless `fixed`: a parameter that only enters the initial state
    (an initial condition) can only be set until initialization ends."""

    positive: bool = False
    fixed: bool = False


@dataclass(frozen=True)
class System:
    """A continuous or discrete system with named signals, ready for code generation.

    Function signatures (all arguments and results are dense column vectors):
      - `initial_state(p) -> x0`: the state at initialization, from the parameters;
      - continuous: `dynamics(x, u, p) -> dx/dt`, integrated by fixed-step RK4 sub-steps inside
        fmi2DoStep, the inputs held constant over the communication step;
      - discrete: `dynamics(x, u, p) -> x_next`, applied once per communication step, which must
        equal `sample_time`;
      - `output(x, u, p, w) -> y`: the outputs at the current communication point, where `w`
        holds `n_noise` independent standard normal samples drawn by the FMU's seeded random
        number generator once per communication step (w is empty when n_noise == 0);
      - with a `network` (an embedded ONNX graph, see fmu.network), `output(x, u, p, w, r)`
        takes a fifth argument: the network's result at this communication point, computed
        every `network.period` steps from `network.input_function(x, u, p)` and extrapolated
        linearly from its last two results in between.
    """

    name: str
    description: str
    kind: Literal["continuous", "discrete"]
    states: tuple[Variable, ...]
    inputs: tuple[Variable, ...]
    outputs: tuple[Variable, ...]
    parameters: tuple[Parameter, ...]
    initial_state: ca.Function
    dynamics: ca.Function
    output: ca.Function
    n_noise: int = 0
    sample_time: float | None = None
    max_substep: float = 1e-3
    extra: dict[str, str] = field(default_factory=dict)
    network: Network | None = None
