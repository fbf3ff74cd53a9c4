"""Toy systems and independent references for the tests of fmu/.

- `duffing()`: a continuous, nonlinear, noisy Duffing oscillator driven by a force;
- `discrete_pi()`: a discrete PI controller with output saturation (sample time 1 ms);
- `rk4_reference()`: the FMU's integration scheme re-done in Python on the CasADi functions;
- `normals()`: the FMU's noise generator (xoshiro256** + Box-Muller) re-done in Python;
- `LoggedSlave`: an fmpy FMU2Slave whose log messages are collected in a list;
- `build_toy()`, `status_of()`: building into pytest's temporary folder, FMI status of a call;
- `misbehaving()`: a built FMU rebuilt from its sources with FMI functions of its own, for the
  faults of FMUs from elsewhere (a crash in one call, a state restore that is slightly off).
"""

from __future__ import annotations

import math
import re
import shutil
import zipfile
from pathlib import Path

import casadi as ca
import fmpy
import numpy as np
import pytest
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

from flexff.fmu import build_fmu
from flexff.fmu.compile import run_compiler
from flexff.fmu.system import Parameter, System, Variable

DUFFING_PARAMS = {"m": 0.5, "k": 200.0, "c": 0.4, "alpha": 5e4, "q0": 0.05, "v0": 0.0,
                  "sigma": 1e-3}


def duffing(name: str = "duffing", max_substep: float = 2.5e-4, **starts: float) -> System:
    """m q'' + c q' + k q + alpha q^3 = F, measured position q + sigma w."""
    values = {**DUFFING_PARAMS, **starts}
    x, u, w = ca.SX.sym("x", 2), ca.SX.sym("u", 1), ca.SX.sym("w", 1)
    p = ca.SX.sym("p", len(values))
    m, k, c, alpha, q0, v0, sigma = ca.vertsplit(p)
    q, v = x[0], x[1]
    acc = (u[0] - c * v - k * q - alpha * q**3) / m
    units = {"m": "kg", "k": "N/m", "c": "N.s/m", "alpha": "N/m3", "q0": "m", "v0": "m/s",
             "sigma": "m"}
    return System(
        name=name,
        description="Duffing oscillator driven by a force, with a noisy position sensor",
        kind="continuous",
        states=(Variable("q", "m", "position"), Variable("v", "m/s", "velocity")),
        inputs=(Variable("F", "N", "applied force"),),
        outputs=(Variable("q_meas", "m", "measured position"), Variable("q_true", "m"),
                 Variable("v_true", "m/s"), Variable("a", "m/s2", "acceleration")),
        parameters=tuple(Parameter(n, units[n], start=values[n], positive=n in ("m", "k", "c"))
                         for n in values),
        initial_state=ca.Function("x0", [p], [ca.vertcat(q0, v0)]),
        dynamics=ca.Function("f", [x, u, p], [ca.vertcat(v, acc)]),
        output=ca.Function("h", [x, u, p, w], [ca.vertcat(q + sigma * w[0], q, v, acc)]),
        n_noise=1,
        max_substep=max_substep,
    )


def discrete_pi(name: str = "pi", sample_time: float = 1e-3) -> System:
    """u = sat(kp e + ki I), I+ = I + Ts e, e = r - y."""
    x, u = ca.SX.sym("x", 1), ca.SX.sym("u", 2)
    p, w = ca.SX.sym("p", 3), ca.SX.sym("w", 0)
    kp, ki, umax = ca.vertsplit(p)
    e = u[0] - u[1]
    out = ca.fmin(ca.fmax(kp * e + ki * x[0], -umax), umax)
    return System(
        name=name,
        description="discrete PI controller with saturation",
        kind="discrete",
        states=(Variable("I", "m.s", "integral of the error"),),
        inputs=(Variable("r", "m"), Variable("y", "m")),
        outputs=(Variable("u", "N", "saturated command"),),
        parameters=(Parameter("kp", "N/m", start=50.0, positive=True),
                    Parameter("ki", "N/(m.s)", start=500.0, positive=True),
                    Parameter("umax", "N", start=2.0, positive=True)),
        initial_state=ca.Function("x0", [p], [ca.DM.zeros(1)]),
        dynamics=ca.Function("f", [x, u, p], [x + sample_time * e]),
        output=ca.Function("h", [x, u, p, w], [out]),
        sample_time=sample_time,
    )


def rk4_reference(system: System, params: dict[str, float], forces: np.ndarray,
                  steps: list[tuple[float, int]]) -> np.ndarray:
    """States at every communication point: RK4 in Python on the system's CasADi functions.

    `steps` gives (communication step size, number of equal RK4 sub-steps) for each step;
    `params` overrides the parameter start values; force k is held over step k.
    """
    p = ca.DM([params.get(v.name, v.start) for v in system.parameters])
    x = np.array(system.initial_state(p)).ravel()
    out = [x]
    for u, (h, n) in zip(forces, steps, strict=True):
        x = rk4(lambda state, u=u: np.array(system.dynamics(state, u, p)).ravel(), x, h / n, n)
        out.append(x)
    return np.array(out)


def rk4(f, x, dt: float, substeps: int):
    """`substeps` RK4 steps of length dt from x under dx/dt = f(x), in the FMU wrapper's order
    of operations (fmu/c/wrapper.c: rk4_step), on numbers or on CasADi symbols alike."""
    for _ in range(substeps):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


MASK = (1 << 64) - 1


def normals(seed: int, count: int) -> list[float]:
    """The first `count` standard normals of the FMU's generator for `seed`."""
    def splitmix(state: int) -> tuple[int, int]:
        state = (state + 0x9E3779B97F4A7C15) & MASK
        z = state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
        return state, z ^ (z >> 31)

    def rotl(v: int, k: int) -> int:
        return ((v << k) | (v >> (64 - k))) & MASK

    sm = seed & MASK
    s = []
    for _ in range(4):
        sm, z = splitmix(sm)
        s.append(z)

    def uniform() -> float:
        result = (rotl((s[1] * 5) & MASK, 7) * 9) & MASK
        t = (s[1] << 17) & MASK
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = rotl(s[3], 45)
        return ((result >> 11) + 0.5) * 2.0**-53

    out: list[float] = []
    while len(out) < count:
        radius = math.sqrt(-2.0 * math.log(uniform()))
        angle = 2.0 * math.pi * uniform()
        out += [radius * math.cos(angle), radius * math.sin(angle)]
    return out[:count]


def logging_callbacks() -> tuple[fmi2CallbackFunctions, list[tuple[int, str, str]]]:
    """FMI callbacks whose logger appends (status, category, message) to the returned list."""
    messages: list[tuple[int, str, str]] = []

    def logger(env, instance, status, category, message):
        messages.append((status, category.decode(), message.decode()))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    return callbacks, messages


class LoggedSlave:
    """An instantiated FMU2Slave with captured log messages and name -> value reference map."""

    def __init__(self, fmu_path, instance_name: str = "toy", logging_on: bool = False,
                 unzipdir: str | None = None):
        md = read_model_description(fmu_path)
        self.guid = md.guid
        self._owns_unzipdir = unzipdir is None
        self.unzipdir = unzipdir or extract(fmu_path)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=self.unzipdir,
                               modelIdentifier=md.coSimulation.modelIdentifier,
                               instanceName=instance_name)
        self.callbacks, self.messages = logging_callbacks()
        self.slave.instantiate(callbacks=self.callbacks, loggingOn=logging_on)

    def log(self) -> str:
        """All logged messages, one per line."""
        return "\n".join(m for _, _, m in self.messages)

    def initialize(self, seed: int | None = None, **params: float) -> None:
        """Set up at t = 0, set the given parameters in initialization mode, and leave it."""
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        for name, value in params.items():
            self.slave.setReal([self.vr[name]], [value])
        if seed is not None:
            self.slave.setInteger([self.vr["seed"]], [seed])
        self.slave.exitInitializationMode()

    def get(self, *names: str) -> list[float]:
        return self.slave.getReal([self.vr[n] for n in names])

    def set(self, **values: float) -> None:
        self.slave.setReal([self.vr[n] for n in values], list(values.values()))

    def free(self) -> None:
        """Free the instance, and the extracted FMU if this object extracted it."""
        self.slave.freeInstance()
        if self._owns_unzipdir:
            shutil.rmtree(self.unzipdir, ignore_errors=True)


def build_toy(system: System, tmp_path_factory, fmi_version: int = 2) -> Path:
    """Build a toy FMU (FMI `fmi_version`) into the session's temporary folder, with a
    session-wide build cache."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("FLEXFF_CACHE", str(tmp_path_factory.getbasetemp() / "flexff-cache"))
        return build_fmu(system, tmp_path_factory.mktemp("fmu") / f"{system.name}.fmu",
                         fmi_version)


def status_of(call, *args, **kwargs) -> int:
    """The fmi2Status of a call through fmpy, which raises on statuses above fmi2Warning."""
    try:
        return call(*args, **kwargs)
    except FMICallException as exc:
        return exc.status


def misbehaving(fmu: Path, target: Path, wrappers: str) -> Path:
    """A copy of the flexff FMU `fmu` at `target` whose binary is rebuilt from its sources/
    with the C code `wrappers` appended to fmi2Functions.c. Every FMI function `wrappers`
    defines replaces the FMU's own, which stays callable as `real_<name>` (fmi2DoStep ->
    real_fmi2DoStep)."""
    folder = target.with_suffix(".unpacked")
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder)
    source = folder / "sources" / "fmi2Functions.c"
    text = source.read_text()
    for name in set(re.findall(r"^\w+ (fmi2\w+)\(", wrappers, flags=re.M)):
        text, count = re.subn(rf"^(\w+) {name}\(", rf"\1 real_{name}(", text, flags=re.M)
        assert count == 1, f"{name} is not defined once in {source}"
    source.write_text(text + "\n" + wrappers)
    md = read_model_description(str(fmu))
    sources = [folder / "sources" / f for f in
               md.buildConfigurations[0].sourceFileSets[0].sourceFiles]
    library = folder / "binaries" / fmpy.platform / f"{md.coSimulation.modelIdentifier}.so"
    run_compiler(sources, library, [folder / "sources"], libraries=("-lm", "-ldl"))
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(folder).as_posix())
    shutil.rmtree(folder)
    return target
