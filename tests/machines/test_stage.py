"""The gantry stage (machines.stage) as an FMU: validated, its coupled physics checked against an
energy computed here, run the same by FMPy and libcosim, and its example loop
(flexff/machines/examples/stage.toml: built-in stage and PID) run by `flexff run`."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexff import api
from flexff.blocks.options import OptionError
from flexff.fmu.build import build_fmu
from flexff.fmu.validation import validate_fmu
from flexff.machines.stage import stage_from_options, true_parameters
from tests.runners import run_fmu, run_fmu_libcosim, simulate_with_fmpy

STEP = 1e-3
ROOT = Path(__file__).parents[2]
EXAMPLE = ROOT / "flexff" / "machines" / "examples" / "stage.toml"


@pytest.fixture(scope="module")
def stage(tmp_path_factory):
    return build_fmu(stage_from_options({}, STEP), tmp_path_factory.mktemp("stage") / "s.fmu")


def test_stage_validates(stage):
    assert validate_fmu(stage) == []


def _energy(r, v):
    """Kinetic energy (the carriage at (x - y sin a, y cos a) on the yawing beam) plus the yaw
    spring's, computed here from the states."""
    y, a, vx, vy, va = (r[n] for n in ("y_pos", "yaw_angle", "x_vel", "y_vel", "yaw_rate"))
    cx, cy = vx - vy * np.sin(a) - y * np.cos(a) * va, vy * np.cos(a) - y * np.sin(a) * va
    return (0.5 * v["mass_beam"] * vx**2 + 0.5 * v["inertia_beam"] * va**2
            + 0.5 * v["mass_carriage"] * (cx**2 + cy**2) + 0.5 * v["yaw_stiffness"] * a**2)


def test_stage_couples_the_axes_through_yaw_and_conserves_energy(stage):
    lossless = {"yaw_damping": 0.0, **{f"{k}_{a}": 0.0 for k in (
        "viscous", "coulomb_positive", "coulomb_negative") for a in "xy"}}
    push = {"Fx": lambda t: 50.0 if t < 0.05 else 0.0, "Fy": lambda t: 20.0 if t < 0.05 else 0.0}
    states = ["y_pos", "yaw_angle", "x_vel", "y_vel", "yaw_rate", "yaw"]
    r = simulate_with_fmpy(stage, push, 0.3, states, y_start=0.2, **lossless)
    energy = _energy(r, true_parameters())[r["time"] > 0.06]
    assert np.ptp(energy) < 1e-6 * np.mean(energy)
    assert np.max(np.abs(r["yaw"])) > 1e-6  # an x push off centre turns the beam
    centred = simulate_with_fmpy(stage, {"Fx": lambda t: 50.0, "Fy": lambda t: 0.0}, 0.1,
                                 ["yaw", "y_true"])
    assert np.max(np.abs(centred["yaw"])) == 0.0  # carriage at the centre: no yaw, no drift
    assert np.max(np.abs(centred["y_true"])) == 0.0


@pytest.mark.parametrize(("force", "speed"), [(10.0, (10.0 - 0.9) / 15),
                                              (-10.0, -(10.0 - 0.7) / 15),
                                              (200.0, (80.0 - 0.9) / 15)])
def test_cross_axis_friction_is_asymmetric_and_the_force_saturates(stage, force, speed):
    r = simulate_with_fmpy(stage, {"Fx": lambda t: 0.0, "Fy": lambda t: force}, 2.0, ["vy_true"])
    assert r["vy_true"][-1] == pytest.approx(speed, rel=1e-4)


def test_stage_runs_the_same_under_libcosim(stage):
    """libcosim, the second importer, gives FMPy's samples (noise included: same seed)."""
    steps, rng = 200, np.random.default_rng(7)
    inputs = {"Fx": rng.uniform(-50, 50, steps), "Fy": rng.uniform(-20, 20, steps)}
    start = {"y_start": 0.1, "noise_std": 2e-6, "seed": 5}
    record = ["x", "y", "x_true", "y_true", "yaw"]
    by_fmpy = run_fmu(stage, steps, STEP, inputs, start, record)
    by_libcosim = run_fmu_libcosim(stage, steps, STEP, inputs, start, record)
    for name in record:
        np.testing.assert_allclose(by_libcosim[name], by_fmpy[name][1:], rtol=1e-12,
                                   atol=1e-15, err_msg=name)
    counts = by_fmpy["x"] / 1e-6
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)  # whole encoder counts


def test_the_example_loop_tracks_both_axes(tmp_path):
    """`flexff run` on the shipped example: built-in stage and PID, the [machine]'s metrics."""
    subprocess.run([sys.executable, "-m", "flexff", "run", str(EXAMPLE), "-o", str(tmp_path)],
                   check=True, capture_output=True, cwd=ROOT)
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    rec = api.read(tmp_path).recording
    for axis in "xy":
        assert metrics[axis]["einf"] < 1e-3, axis  # PID alone: under a millimetre
        error = rec[f"{axis}_ref"] - rec[f"stage.{axis}_true"]
        assert np.max(np.abs(error[rec.time > 2.8])) < 2e-5, axis  # settled after the moves


def test_stage_options_are_checked():
    with pytest.raises(OptionError, match="'speed'"):
        stage_from_options({"speed": 1}, STEP)
    with pytest.raises(OptionError, match="axes"):
        stage_from_options({"axes": ["x"]}, STEP)


@pytest.mark.slow
def test_identification_recovers_the_stage_parameters(tmp_path):
    """flexff's data collection and identification on the example loop find each axis's moving
    mass, viscous and Coulomb friction (the coupled yaw mode stays outside the per-axis prior)."""
    data, found = tmp_path / "data", tmp_path / "identified" / "identified.json"
    for command in (["data", "collect", "--config", str(EXAMPLE), "-o", str(data), "--workers",
                     "1", "--trajectories", "6", "2", "--duration", "8"],
                    ["identify", str(data), "-o", str(found.parent)]):
        subprocess.run([sys.executable, "-m", "flexff", *command], check=True,
                       capture_output=True, cwd=ROOT)
    axes = json.loads(found.read_text())["axes"]
    v = true_parameters()
    truth = {"x": (v["mass_beam"] + v["mass_carriage"], v["viscous_x"], v["coulomb_positive_x"],
                   v["coulomb_negative_x"]),
             "y": (v["mass_carriage"], v["viscous_y"], v["coulomb_positive_y"],
                   v["coulomb_negative_y"])}
    for axis, values in truth.items():
        assert axes[axis]["terms"] == ["inertia", "viscous", "coulomb_positive",
                                       "coulomb_negative"]
        np.testing.assert_allclose(axes[axis]["parameters"][:2], values[:2], rtol=0.02)
        np.testing.assert_allclose(axes[axis]["parameters"][2:], values[2:], rtol=0.1)
