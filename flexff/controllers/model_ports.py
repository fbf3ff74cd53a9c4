"""What one exported model asks of its feedforward FMU, as its model card describes it: the
ports that controllers.learned_feedforward builds the one learned feedforward around, made by
the manipulator's card (controllers.learned_feedforward) or a machine's
(controllers.machine_feedforward)."""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

from flexff.fmu.system import Variable


@dataclass(frozen=True)
class ModelPorts:
    """The FMU's input symbol and its variables, the network's inputs and the prior (None:
    none) as expressions of it, the output variables; what the FMU's description says of the
    model (`of`: whose it is, `added`: what it adds to the network), the card's metadata beside
    the common entries, whether the network starts at rest on its first inputs (`primed`) and
    whether the precomputed mode (a table of the manipulator's reference) applies."""

    reference: ca.SX
    inputs: tuple[Variable, ...]
    features: ca.SX
    prior: ca.SX | None
    outputs: tuple[Variable, ...]
    of: str = ""
    added: str = ""
    metadata: dict[str, str] = field(default_factory=dict)
    primed: bool = False
    precomputed: bool = False
