"""The 1-axis drive FMU against independent physics, and the generic PID (series form, built-in
"pid") on it in closed loop."""

import math

import numpy as np
import pytest

from flexff.blocks.pid import pid_system
from flexff.blocks.pid_design import AxisPid, LoopShape
from flexff.fmu.build import build_fmu
from flexff.fmu.validation import validate_fmu
from flexff.machines.drive import DRIVE, drive_system
from tests.runners import run_fmu

FRICTIONLESS = {"viscous": 0.0, "coulomb_positive": 0.0, "coulomb_negative": 0.0,
                "cogging": 0.0, "encoder": 0.0}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("drive")
    return {"drive": build_fmu(drive_system(), folder / "drive.fmu"),
            "pid": build_fmu(pid_system({"x": _loop(DRIVE.mass, effort_limit=50.0)}, 1e-3),
                             folder / "pid.fmu")}


def _loop(mass, **options):
    """The series-form PID of built-in "pid", loop-shaped at 20 Hz around `mass`."""
    return AxisPid(LoopShape(20.0, mass), form="series", **options)


def test_the_fmus_validate(fmus):
    assert validate_fmu(fmus["drive"]) == [] and validate_fmu(fmus["pid"]) == []


def test_a_constant_force_accelerates_the_whole_mass(fmus):
    """Without friction the carriage and its mounted load move as one mass below the mount's
    250 Hz: x = F t^2 / (2 m), the mount's ringing a few micrometres at most."""
    out = run_fmu(fmus["drive"], 500, 1e-3, {"F": 4.0}, FRICTIONLESS)
    t = out["time"]
    np.testing.assert_allclose(out["x_true"], 4.0 * t**2 / (2 * DRIVE.mass), atol=2e-6)


def test_coulomb_friction_holds_a_force_below_it_and_the_encoder_counts(fmus):
    out = run_fmu(fmus["drive"], 300, 1e-3, {"F": 1.0}, {"cogging": 0.0})
    assert np.abs(out["v_true"][-100:]).max() < 2e-3  # creeps within the tanh's width only
    moving = run_fmu(fmus["drive"], 300, 1e-3, {"F": 10.0})
    steps = moving["x"] / DRIVE.encoder
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
    assert np.abs(moving["x"] - moving["x_true"]).max() <= DRIVE.encoder / 2 + 1e-12


def test_the_effort_limit_saturates(fmus):
    """1e4 N asked, the limit's 200 N given; the mount rings by F m_load / (m k) = 40 um."""
    out = run_fmu(fmus["drive"], 200, 1e-3, {"F": 1e4}, FRICTIONLESS)
    t = out["time"]
    np.testing.assert_allclose(out["x_true"], DRIVE.force_limit * t**2 / (2 * DRIVE.mass),
                               atol=5e-5)


def test_the_pid_follows_its_design_and_holds_its_integrator_at_the_limit(fmus):
    design = _loop(DRIVE.mass, effort_limit=50.0).state_space(1e-3)
    error = np.full(50, 1e-4)
    out = run_fmu(fmus["pid"], 50, 1e-3, {"x_ref": 1e-4, "x": 0.0, "x_ff": 0.5})
    state, expected = np.zeros(design.A.shape[0]), []
    for e in error:
        expected.append(float((design.C @ state)[0] + design.D[0, 0] * e))
        state = design.A @ state + design.B[:, 0] * e
    np.testing.assert_allclose(out["x_fb"][:50], expected, rtol=1e-9)
    np.testing.assert_allclose(out["x_effort"], out["x_fb"] + 0.5)
    saturated = run_fmu(fmus["pid"], 2000, 1e-3, {"x_ref": 1.0, "x": 0.0, "x_ff": 0.0})
    assert saturated["x_effort"].max() == pytest.approx(50.0)
    states = [f"x_pid{k}" for k in range(design.A.shape[0])]
    held = run_fmu(fmus["pid"], 2000, 1e-3, {"x_ref": 1.0, "x": 0.0, "x_ff": 0.0},
                   record=states)
    for name in states:  # held at the limit, not winding up
        assert np.abs(np.diff(held[name][-1000:])).max() == 0.0


def test_a_mass_loop_is_stable_with_its_designed_margins():
    design = _loop(2.0).state_space(1e-3)
    assert np.abs(np.linalg.eigvals(design.A)).max() <= 1.0 + 1e-12
    notched = _loop(2.0, notch_hz=250.0, lowpass_hz=300.0).state_space(1e-3)
    w = 2 * math.pi * 250.0
    assert abs(notched.response(w)[0]) < 0.2 * abs(design.response(w)[0])
