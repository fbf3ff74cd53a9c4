"""The drive FMU (machines.drive) against closed-form physics beyond tests/machines/test_drive.py:
its two-mass resonance, energy with cogging, its asymmetric friction; and in closed loop under
the PID with tunable gains, run by `flexff run` from a general-form configuration."""

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from scipy.linalg import expm

from flexff import api
from flexff.blocks.pid_options import pid_gains_from_options
from flexff.fmu.build import build_fmu
from flexff.machines.drive import DRIVE, drive_system, effort_of

STEP = 1e-3
QUIET = {"coulomb_positive": 0.0, "coulomb_negative": 0.0, "cogging": 0.0}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("drive_physics")
    pid = pid_gains_from_options({"axes": ["x"], "crossover_hz": 30.0, "mass": DRIVE.mass,
                            "effort_limit": DRIVE.force_limit}, STEP)
    return {"drive": build_fmu(drive_system(), folder / "drive.fmu"),
            "pid": build_fmu(pid, folder / "pid.fmu")}


def _run(path, force, stop, outputs, **start):
    """FMPy run at STEP with the force F(t) sampled at every step."""
    t = np.arange(0.0, stop + STEP / 2, STEP)
    table = np.array(list(zip(t, np.vectorize(force, otypes=[float])(t))),
                     dtype=[("time", float), ("F", float)])
    return simulate_fmu(str(path), stop_time=stop, step_size=STEP, output_interval=STEP,
                        input=table, output=outputs, start_values=start)


def _mount(p=DRIVE):
    w = 2 * math.pi * p.mount_hz
    return p.m_load * w**2, 2 * p.mount_damping * p.m_load * w


def test_without_friction_the_drive_is_the_linear_two_mass_model(fmus):
    """Friction and cogging off, a 10 N step: exp(A t) of carriage and load on the mount."""
    force, (k, c) = 10.0, _mount()
    r = _run(fmus["drive"], lambda t: force, 0.1, ["x_true", "v_true", "x_load"], **QUIET)
    m1, m2, b = DRIVE.m_motor, DRIVE.m_load, DRIVE.viscous
    a = np.array([[0, 1, 0, 0, 0], [-k / m1, -(b + c) / m1, k / m1, c / m1, 1 / m1],
                  [0, 0, 0, 1, 0], [k / m2, c / m2, -k / m2, -c / m2, 0], [0] * 5])
    exact = np.array([expm(a * t) @ [0, 0, 0, 0, force] for t in r["time"]])
    np.testing.assert_allclose(r["x_true"], exact[:, 0], atol=1e-9)
    np.testing.assert_allclose(r["v_true"], exact[:, 1], atol=1e-6)
    np.testing.assert_allclose(r["x_load"], exact[:, 2], atol=1e-9)


def test_energy_with_cogging_is_conserved_without_losses(fmus):
    """No friction or damping: kinetic + mount spring + cogging potential stays constant after a
    push, so the cogging force is the gradient of -cogging pitch / 2 pi cos(2 pi x / pitch)."""
    start = {**QUIET, "cogging": 0.5, "viscous": 0.0, "mount_damping": 0.0}
    r = _run(fmus["drive"], lambda t: 5.0 if t < 0.05 else 0.0, 0.3,
             ["x_carriage", "v_carriage", "x_mount", "v_mount"], **start)
    x1, v1, x2, v2 = (r[n] for n in ("x_carriage", "v_carriage", "x_mount", "v_mount"))
    k, pitch = _mount()[0], DRIVE.pitch
    energy = (0.5 * DRIVE.m_motor * v1**2 + 0.5 * DRIVE.m_load * v2**2 + 0.5 * k * (x1 - x2)**2
              - 0.5 * pitch / (2 * math.pi) * np.cos(2 * math.pi * x1 / pitch))
    after = r["time"] > 0.06
    assert np.ptp(energy[after]) < 1e-6 * np.mean(0.5 * DRIVE.m_motor * v1[after] ** 2)
    assert np.ptp(x1) > pitch  # it rode over the cogging ripple


@pytest.mark.parametrize(("force", "speed"), [(5.0, (5.0 - 1.5) / 20), (-5.0, -(5.0 - 1.2) / 20),
                                              (300.0, (200.0 - 1.5) / 20)])
def test_coulomb_friction_is_asymmetric_and_the_force_saturates(fmus, force, speed):
    r = _run(fmus["drive"], lambda t: force, 1.0, ["v_true"], cogging=0.0)
    assert r["v_true"][-1] == pytest.approx(speed, rel=1e-4)


ROUGH = {"stribeck": 1.0, "stribeck_velocity": 0.01, "friction_ripple": 0.8,
         "friction_period": 0.037, "force_ripple": 0.05, "ripple_pitch": 0.023, "spring": 40.0,
         "spring_cubic": 2e4}  # flexff/machines/examples/drive-rough.toml's, but the current lag


def test_the_rough_effects_are_the_inverse_dynamics_they_name(fmus):
    """Stribeck and position-dependent friction, force ripple, a cubic spring: the effort of
    effort_of along a move, fed open loop, moves the drive along it (7 um off in 1 s; the
    same effort without the effects leaves it by 0.1 m)."""
    def motion(t):
        w = 2 * math.pi
        return 0.03 * (1 - np.cos(w * t)), 0.03 * w * np.sin(w * t), 0.03 * w**2 * np.cos(w * t)
    rough = replace(DRIVE, **ROUGH)
    effort = {round(t / STEP): effort_of(rough, *motion(t + STEP / 2), np)
              for t in np.arange(0.0, 1.0 + STEP / 2, STEP)}
    for start, within in ((ROUGH, 2e-5), ({}, None)):
        r = _run(fmus["drive"], lambda t: effort[round(t / STEP)], 1.0, ["x_true"], **start)
        off = np.max(np.abs(r["x_true"] - motion(r["time"])[0]))
        assert off < within if within else off > 0.05


def test_the_current_loop_lags_the_force_by_its_time_constant(fmus):
    r = _run(fmus["drive"], lambda t: 10.0, 0.05, ["F_motor"], current_lag=0.005)
    np.testing.assert_allclose(r["F_motor"], 10.0 * (1 - np.exp(-r["time"] / 0.005)),
                               atol=1e-7)


def test_closed_loop_under_the_tunable_pid_tracks_a_setpoint_move(tmp_path, fmus):
    times = np.arange(0.0, 2.0 + STEP / 2, 0.01)
    reference = np.interp(times, [0.0, 0.2, 0.4, 2.0], [0.0, 0.0, 0.005, 0.005])
    (tmp_path / "reference.csv").write_text("time,x_ref\n" + "".join(
        f"{t:.10g},{x:.10g}\n" for t, x in zip(times, reference)))
    config = tmp_path / "loop.toml"
    config.write_text(f"""
[run]
step = {STEP}
stop = 2.0

[fmu.pid]
path = "{fmus["pid"].as_posix()}"

[fmu.drive]
path = "{fmus["drive"].as_posix()}"

[[source]]
kind = "csv"
path = "reference.csv"

[[source]]
kind = "constant"
values = {{ x_ff = 0.0 }}

[[connection]]
from = "pid.x_effort"
to = "drive.F"
""")
    out = tmp_path / "out"
    subprocess.run([sys.executable, "-m", "flexff", "run", str(config), "-o", str(out)],
                   check=True, capture_output=True, cwd=Path(__file__).parents[2])
    rec = api.read(out).recording
    error = rec["x_ref"] - rec["drive.x_true"]
    settled = rec.time > 1.0
    assert np.max(np.abs(error)) < 5e-4
    assert np.max(np.abs(error[settled])) < 2e-6
    assert np.max(np.abs(rec["pid.x_effort"][settled])) < 10.0  # at rest, far from the limit
