"""Physical parameters of the redundantly actuated flexure manipulator, with units.

Berendsen's identified values are not public. The thesis gives the arm lengths (0.3086 m, the
table's "mm" is a typo: the workspace radius is 0.05 m), the motor (torque constant
36.9 mNm/A, nominal torque 0.128 Nm: a Maxon EC 45 flat 70 W), the 2048 counts/rev encoders,
the Escon 50/5 amplifiers and the lowest natural frequency at the centre, about 1.7 Hz. The
remaining values are chosen as plausible for light aluminium arms on a thin steel base; the
flexure stiffness is then set so that the lowest natural frequency at the centre is 1.70 Hz
(checked by `plant.analysis.modes` and the tests).

Every field is a float or a 3-tuple of floats (one entry per kinematic chain), so the same
dataclass can hold CasADi symbols: `from_vector` of an SX vector gives an instance whose entries
are SX scalars, and the dynamics are written once for numbers and symbols alike.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import Field, dataclass, field, fields, replace
from typing import Any, TypeAlias

from flexff.fmu.errors import InputError

CHAINS = (1, 2, 3)
MOTOR_FRICTION = ("tau_coulomb", "b_viscous", "w_stribeck")  # fields of plant.actuator's model
# a per-chain field: one entry per chain (numbers, or CasADi symbols from `from_vector`); the
# name is what `_is_per_chain` looks for in a field's (string) annotation
PerChain: TypeAlias = tuple[float, float, float]


def _param(unit: str, description: str, positive: bool = True) -> Any:
    return field(metadata={"unit": unit, "description": description, "positive": positive})


@dataclass(frozen=True)
class PlantParameters:
    """All physical parameters of the plant; per-chain values are 3-tuples (chains 1, 2, 3)."""

    # geometry
    l_up: float = _param("m", "upper arm length, shoulder to elbow hinge")
    l_low: float = _param("m", "lower arm length, elbow to wrist hinge")
    r_mount: float = _param("m", "radius of the circle on which the three motors are mounted")
    workspace_radius: float = _param("m", "radius of the admissible end-effector workspace")
    # rigid bodies (centre of mass on the arm axis)
    m_up: PerChain = _param("kg", "upper arm mass")
    j_up: PerChain = _param("kg*m^2", "upper arm inertia about its centre of mass")
    c_up: PerChain = _param("m", "shoulder hinge to upper arm centre of mass")
    m_low: PerChain = _param("kg", "lower arm mass")
    j_low: PerChain = _param("kg*m^2", "lower arm inertia about its centre of mass")
    c_low: PerChain = _param("m", "elbow hinge to lower arm centre of mass")
    m_ee: float = _param("kg", "wrist (end-effector) mass")
    j_ee: float = _param("kg*m^2", "wrist (end-effector) inertia about its centre")
    # flexure hinges: rotational stiffness and light damping
    k_s: PerChain = _param("N*m/rad", "shoulder flexure stiffness")
    k_e: PerChain = _param("N*m/rad", "elbow flexure stiffness")
    k_w: PerChain = _param("N*m/rad", "wrist flexure stiffness (lower arm to wrist)")
    d_s: PerChain = _param("N*m*s/rad", "shoulder flexure damping", positive=False)
    d_e: PerChain = _param("N*m*s/rad", "elbow flexure damping", positive=False)
    d_w: PerChain = _param("N*m*s/rad", "wrist flexure damping", positive=False)
    # motors and amplifiers
    j_rotor: PerChain = _param("kg*m^2", "motor rotor inertia")
    k_t: PerChain = _param("N*m/A", "motor torque constant")
    i_max: float = _param("A", "amplifier current limit (saturation)")
    # encoder
    encoder_counts: float = _param("1/rev", "encoder resolution in counts per revolution")
    encoder_quantization: float = _param(
        "1", "1: the encoder reads whole counts; 0: the exact angle (the ideal sensor of the "
        "thesis's simulation model)", positive=False)
    # non-ideal effects (zero switches them off, except the tool mount, which is structural)
    tau_coulomb: PerChain = _param("N*m", "Coulomb friction torque at the motor", positive=False)
    b_viscous: PerChain = _param("N*m*s/rad", "viscous friction at the motor", positive=False)
    w_stribeck: float = _param("rad/s", "velocity scale of the smooth (tanh) Coulomb friction")
    m_tool: float = _param("kg", "tool on a compliant mount at the wrist (parasitic mode)")
    k_tool: float = _param("N/m", "stiffness of the tool mount, per direction")
    d_tool: float = _param("N*s/m", "damping of the tool mount, per direction", positive=False)
    noise_std: float = _param("rad", "standard deviation of the encoder noise", positive=False)

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_vector(cls, vector: Any) -> PlantParameters:
        """Rebuild from a flat vector ordered as `names()` (numbers or CasADi expressions)."""
        values: dict[str, Any] = {}
        k = 0
        for f in fields(cls):
            if _is_per_chain(f):
                values[f.name] = tuple(vector[k + j] for j in range(3))
                k += 3
            else:
                values[f.name] = vector[k]
                k += 1
        return cls(**values)

    # -- flat views ---------------------------------------------------------------------------
    @classmethod
    def names(cls) -> list[str]:
        """Flat parameter names: per-chain fields get suffixes 1, 2, 3 (e.g. `m_up2`)."""
        return [name for name, *_ in cls._flat_fields()]

    @classmethod
    def _flat_fields(cls) -> Iterator[tuple[str, str, Any, int | None]]:
        for f in fields(cls):
            if _is_per_chain(f):
                for j, chain in enumerate(CHAINS):
                    yield f"{f.name}{chain}", f.name, f, j
            else:
                yield f.name, f.name, f, None

    def vector(self) -> list[float]:
        """Flat values in the order of `names()`."""
        return [v for _, v, *_ in self.describe()]

    def describe(self) -> list[tuple[str, Any, str, str, bool]]:
        """(name, value, unit, description, must_be_positive) of every flat parameter."""
        rows = []
        for name, attr, f, j in self._flat_fields():
            value = getattr(self, attr)
            value = value[j] if j is not None else value
            chain = f" (chain {j + 1})" if j is not None else ""
            rows.append((name, value, f.metadata["unit"], f.metadata["description"] + chain,
                         f.metadata["positive"]))
        return rows

    def with_values(self, **overrides: float) -> PlantParameters:
        """Copy with flat parameters replaced by name (`m_up2=0.3`, `l_up=0.31`), validated."""
        unknown = sorted(set(overrides) - set(self.names()))
        if unknown:
            raise InputError(f"unknown plant parameter(s) {unknown}; known: {self.names()}")
        flat = dict(zip(self.names(), self.vector()))
        flat.update({k: float(v) for k, v in overrides.items()})
        result = self.from_vector([flat[n] for n in self.names()])
        result.validate()
        return result

    def flat_values(self, *fields_: str) -> dict[str, float]:
        """The flat parameters of the named fields: `flat_values("k_t")` gives k_t1, k_t2,
        k_t3; the names and order of `names()`, ready for `with_values`."""
        unknown = sorted(set(fields_) - {f.name for f in fields(self)})
        if unknown:
            raise ValueError(f"unknown plant parameter field(s) {unknown}")
        return {name: getattr(self, attr) if j is None else getattr(self, attr)[j]
                for name, attr, _, j in self._flat_fields() if attr in fields_}

    def validate(self) -> None:
        """Raise InputError naming every parameter that is not finite or not positive."""
        problems = []
        for name, value, unit, _, positive in self.describe():
            if not math.isfinite(value):
                problems.append(f"{name} = {value} {unit} is not finite")
            elif positive and value <= 0:
                problems.append(f"{name} = {value} {unit} must be positive")
            elif value < 0:
                problems.append(f"{name} = {value} {unit} must not be negative")
        if self.encoder_quantization not in (0.0, 1.0):
            problems.append(f"encoder_quantization = {self.encoder_quantization} must be 0 or 1")
        if self.l_up + self.l_low <= self.r_mount + self.workspace_radius:
            problems.append("l_up + l_low must exceed r_mount + workspace_radius (reach)")
        if problems:
            raise InputError("invalid plant parameters: " + "; ".join(problems))

    def scaled(self, **factors: tuple[float, ...] | float) -> PlantParameters:
        """Copy with fields multiplied by factors (a 3-tuple scales chains separately)."""
        changes: dict[str, Any] = {}
        for name, factor in factors.items():
            value = getattr(self, name)
            if isinstance(value, tuple):
                factor = factor if isinstance(factor, tuple) else (factor,) * 3
                changes[name] = tuple(v * s for v, s in zip(value, factor))
            else:
                changes[name] = value * factor
        return replace(self, **changes)


def _is_per_chain(f: Field[Any]) -> bool:
    return f.type in ("PerChain", PerChain)


def _rod(mass: float, length: float) -> float:
    """Inertia of a slender rod about its centre of mass."""
    return mass * length**2 / 12.0


def _three(value: float) -> tuple[float, float, float]:
    return (value, value, value)


# Chosen values and why:
#  - r_mount = sqrt(2) * l: the elbows stand at 90 degrees at the centre, the best-conditioned
#    pose of a symmetric five-bar-like chain (equal arms); every mount is 0.436 m from the centre.
#  - arms: thin-walled aluminium tubes, 0.10 kg (upper, with its hub) and 0.06 kg (lower),
#    centres of mass at mid length; the wrist hinge block weighs 0.05 kg. Light arms keep the
#    flexure stiffness, and so the current that holds the wrist off-centre, within the motors'
#    reach: 8.1 A at the 0.05 m workspace edge in the worst direction.
#  - rotor inertia 181 g*cm^2: EC 45 flat class rotor (the 36.9 mNm/A, 0.128 Nm motor).
#  - current limit 10 A: below the 15 A peak of the Escon 50/5 amplifier the thesis names, and
#    above the 8.1 A that holds the wrist at the workspace edge.
#  - all nine flexures share one stiffness, solved for a 1.70 Hz lowest mode at the centre;
#    damping is stiffness-proportional for about 1 % modal damping at that mode ("light").
_L = 0.3086
_M_UP, _M_LOW = 0.10, 0.06
_K_FLEX = 0.39892
_D_FLEX = _K_FLEX * 2 * 0.01 / (2 * math.pi * 1.70)
# the tool mount (hardware variant only): 50 g on a mount tuned to 36.4 Hz alone, 40 Hz
# against the moving wrist, 2 % damped
_M_TOOL = 0.05
_K_TOOL = _M_TOOL * (2 * math.pi * 36.4) ** 2
_D_TOOL = 2 * 0.02 * math.sqrt(_K_TOOL * _M_TOOL)

NOMINAL = PlantParameters(
    l_up=_L, l_low=_L, r_mount=math.sqrt(2) * _L, workspace_radius=0.05,
    m_up=_three(_M_UP), j_up=_three(_rod(_M_UP, _L)), c_up=_three(_L / 2),
    m_low=_three(_M_LOW), j_low=_three(_rod(_M_LOW, _L)), c_low=_three(_L / 2),
    m_ee=0.05, j_ee=5.0e-5,
    k_s=_three(_K_FLEX), k_e=_three(_K_FLEX), k_w=_three(_K_FLEX),
    d_s=_three(_D_FLEX), d_e=_three(_D_FLEX), d_w=_three(_D_FLEX),
    j_rotor=_three(1.81e-5), k_t=_three(36.9e-3), i_max=10.0,
    encoder_counts=2048.0, encoder_quantization=0.0,
    tau_coulomb=_three(0.0), b_viscous=_three(0.0), w_stribeck=0.01,
    m_tool=_M_TOOL, k_tool=_K_TOOL, d_tool=_D_TOOL,
    noise_std=0.0,
)

# The "hardware" plant: the true machine differs from the nominal model the controllers and the
# rigid-body feedforward use. Mismatch: heavier, unequal arms and wrist (extra cabling, glue,
# bolts), flexures 4-9 % off (thickness tolerance), torque constants 2-4 % low. Coulomb
# friction of about 7 mNm per motor (an EC 45 flat draws ~0.2 A without load), some viscous
# friction, a 50 g tool on a compliant wrist mount whose mode lies near 40 Hz (well above the
# 2 Hz crossover; the thesis's notch filter targets such a parasitic mode; its static deflection
# under the reference's accelerations stays below 0.1 mm) and encoder noise of a third of a
# count before quantization.
HARDWARE_MISMATCH: dict[str, tuple[float, ...] | float] = {
    "m_up": (1.06, 1.10, 1.03), "j_up": (1.06, 1.10, 1.03),
    "m_low": (1.05, 0.97, 1.08), "j_low": (1.05, 0.97, 1.08),
    "m_ee": 1.25, "j_ee": 1.25,
    "k_s": (0.95, 1.06, 0.92), "k_e": (1.04, 0.96, 0.91), "k_w": (0.97, 1.09, 1.0),
    "d_s": 3.0, "d_e": 3.0, "d_w": 3.0,
    "k_t": (0.97, 0.98, 0.96),
}

HARDWARE = replace(
    NOMINAL.scaled(**HARDWARE_MISMATCH),
    tau_coulomb=_three(7.0e-3), b_viscous=_three(2.0e-4),
    encoder_quantization=1.0, noise_std=1.0e-3,
)
