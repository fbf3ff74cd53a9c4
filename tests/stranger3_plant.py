"""A stranger-like 3-axis plant for the tests and for measuring the learned models on: built by
flexff, a rotary axis r carrying an arm whose load
slides on it (inertia growing with the linear axis z's extension, Coriolis and centrifugal
coupling), a linear axis y carrying z, and z lifting against gravity; each axis with viscous
and Coulomb friction (a smooth tanh). The loop: flexff's PID per axis, a reference from the
excitation (synchronised moves). `python -m tests.stranger3_plant FOLDER` writes the FMU, the
reference and the loop (stranger3.toml) for `flexff evaluate --config FOLDER/stranger3.toml`."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import tomli_w

from flexff.cosim.machine import parse_machine
from flexff.fmu import build_fmu
from flexff.fmu.system import Parameter, System, Variable
from flexff.learning.excitation import excitation_set, write_table

J0, ML, L0 = 0.05, 1.0, 0.3        # kg m2, kg (the load on the arm), m (its distance at z = 0)
MY, MZ, G = 4.0, 2.0, 9.81
DAMP = (0.2, 15.0, 10.0)            # N.m.s/rad, N.s/m, N.s/m
COULOMB = (0.15, 2.0, 1.5)          # N.m, N, N
W = (2e-3, 1e-3, 1e-3)


def plant() -> System:
    """The plant: torque and forces in, the three positions out."""
    x, u = ca.SX.sym("x", 6), ca.SX.sym("u", 3)
    p, w = ca.SX.sym("p", 1), ca.SX.sym("w", 0)
    r, y, z, wr, vy, vz = (x[k] for k in range(6))
    radius = L0 + z
    friction = [DAMP[k] * x[3 + k] + COULOMB[k] * ca.tanh(x[3 + k] / W[k]) for k in range(3)]
    inertia = J0 + ML * radius**2
    ar = (u[0] - friction[0] - 2 * ML * radius * vz * wr) / inertia
    ay = (u[1] - friction[1]) / (MY + MZ)
    az = (u[2] - friction[2] - MZ * G + ML * radius * wr**2) / MZ
    return System(name="stranger3", description="rotary arm, gantry y, lift z", kind="continuous",
                  states=(Variable("r", "rad"), Variable("y", "m"), Variable("z", "m"),
                          Variable("wr", "rad/s"), Variable("vy", "m/s"), Variable("vz", "m/s")),
                  inputs=(Variable("T", "N.m"), Variable("Fy", "N"), Variable("Fz", "N")),
                  outputs=(Variable("r_out", "rad"), Variable("y_out", "m"),
                           Variable("z_out", "m")),
                  parameters=(Parameter("unused", "1", start=0.0),),
                  initial_state=ca.Function("x0", [p], [ca.DM.zeros(6)]),
                  dynamics=ca.Function("f", [x, u, p], [ca.vertcat(wr, vy, vz, ar, ay, az)]),
                  output=ca.Function("h", [x, u, p, w], [ca.vertcat(r, y, z)]),
                  max_substep=2.5e-4)


def write_loop(folder: Path) -> Path:
    """The plant's FMU, a 10 s reference and the loop under PID alone in `folder`; the loop."""
    folder.mkdir(parents=True, exist_ok=True)
    build_fmu(plant(), folder / "stranger3.fmu")
    axes = [("r", "rad", "N.m", 0.5, 1.5, 10.0, "r_out", "T", J0 + ML * L0**2),
            ("y", "m", "N", 0.05, 0.25, 2.5, "y_out", "Fy", MY + MZ),
            ("z", "m", "N", 0.05, 0.25, 2.5, "z_out", "Fz", MZ)]
    machine = {"name": "stranger 3-axis", "axis": [
        {"name": a, "unit": unit, "measured": f"plant.{out}", "feedforward": f"pid.{a}_ff",
         "effort": f"pid.{a}_effort", "effort_unit": eu, "range": [-rng, rng],
         "velocity": vel, "acceleration": acc}
        for a, unit, eu, rng, vel, acc, out, _, _ in axes]}
    reference = excitation_set(parse_machine(machine, "m"), 1, 0, 10.0, 1000.0, seed=7,
                               synchronised=True)[0]
    write_table(reference, folder / "reference.csv")
    table = {"run": {"step": 0.001, "stop": 10.0},
             "fmu": {"pid": {"builtin": "pid", "axes": [
                 {"name": a, "unit": unit, "effort_unit": eu, "mass": mass, "crossover_hz": 20.0}
                 for a, unit, eu, *_, mass in axes]},
                 "plant": {"path": "stranger3.fmu"}},
             "source": [{"kind": "csv", "path": "reference.csv"},
                        {"kind": "constant", "values": {f"{a[0]}_ff": 0.0 for a in axes}}],
             "connection": [c for a, *_, out, inp, _ in axes for c in (
                 {"from": f"pid.{a}_effort", "to": f"plant.{inp}"},
                 {"from": f"plant.{out}", "to": f"pid.{a}"})],
             "machine": machine}
    (folder / "stranger3.toml").write_text(tomli_w.dumps(table))
    return folder / "stranger3.toml"


if __name__ == "__main__":
    import sys
    write_loop(Path(sys.argv[1]))
