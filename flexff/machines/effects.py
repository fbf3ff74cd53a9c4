"""Non-ideal effects of a machine model, as CasADi expressions (machines.stage uses them): smooth
asymmetric Coulomb friction, zero at rest, effort saturation, encoder counts with noise."""

from __future__ import annotations

from typing import Any

import casadi as ca


def coulomb_friction(velocity: Any, positive: Any, negative: Any, width: Any) -> Any:
    """Friction force [N] opposing the motion: `positive` while moving +, `negative` (a magnitude)
    while moving -, turned by tanh(velocity / width) so fixed-step RK4 sees a continuous force
    that is zero at rest."""
    return -ca.tanh(velocity / width) * ca.if_else(velocity >= 0, positive, negative)


def saturated(effort: Any, limit: Any) -> Any:
    """The effort clipped to [-limit, limit] (the amplifier's limit)."""
    return ca.fmin(ca.fmax(effort, -limit), limit)


def encoder(position: Any, resolution: Any, noise_std: Any, noise: Any) -> Any:
    """An incremental encoder: the position plus noise_std * noise (a standard normal sample),
    rounded to whole counts of `resolution`; a resolution of 0 reads it exactly."""
    read = position + noise_std * noise
    return ca.if_else(resolution > 0, resolution * ca.floor(read / resolution + 0.5), read)
