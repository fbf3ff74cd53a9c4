"""The trajectory sets of data collection: the thesis's counts and test trajectories, references
the run configurations accept, inside the part of the workspace the motors can hold, and the
same on every call."""

import json
import math
from collections import Counter

import casadi as ca
import numpy as np
import pytest

from flexff.controllers.allocation import motor_currents
from flexff.cosim.config import parse_config
from flexff.cosim.references import build_reference
from flexff.learning import trajectories as T
from flexff.learning.trajectories import R_MAX, R_MIN, trajectory_set
from flexff.plant.model import PlantModel

COUNTS = {"sim": {("train", "circle"): 20, ("train", "line-circle"): 10,
                  ("train", "spline"): 14, ("test", "test-circle"): 3,
                  ("test", "test-spline"): 1},
          "hardware": {("train", "circle"): 39, ("train", "spline"): 21,
                       ("test", "test-circle"): 6, ("test", "test-spline"): 4}}


@pytest.fixture(scope="module", params=["sim", "hardware"])
def trajectory_sets(request):
    return trajectory_set(request.param)


def test_counts_names_and_splits(trajectory_sets):
    s = trajectory_sets
    kinds = Counter((t.split, t.name.rsplit("-", 1)[0]) for t in s.trajectories)
    assert kinds == COUNTS[s.name]
    assert len({t.name for t in s.trajectories}) == len(s.trajectories)
    assert all(t.variant == s.variant for t in s.trajectories)
    assert len({t.seed for t in s.trajectories}) == len(s.trajectories)
    assert all(0 < t.seed < 2**31 for t in s.trajectories)
    assert (s.variant, s.sample_rate_hz, s.duration) == {
        "sim": ("nominal", 1000, 15.0), "hardware": ("hardware", 100, 100.0)}[s.name]


def test_the_same_on_every_call(trajectory_sets):
    again = trajectory_set(trajectory_sets.name)
    assert again == trajectory_sets
    # plain data: the references survive JSON unchanged (they go into the manifest)
    for t in trajectory_sets.trajectories:
        assert json.loads(json.dumps(t.reference)) == t.reference


def test_every_reference_is_a_valid_run_inside_the_holdable_disc(trajectory_sets):
    for t in trajectory_sets.trajectories:
        config = parse_config({"reference": dict(t.reference), "plant": {"variant": t.variant}})
        ref = build_reference(config.reference.kind, config.reference.options, 1e-3)
        assert ref.duration == pytest.approx(trajectory_sets.duration, abs=1e-9), t.name
        reach = np.hypot(ref.x, ref.y).max()
        if t.name != "test-circle-01" or trajectory_sets.name != "sim":
            assert reach <= R_MAX + 1e-12, t.name
        if "circle" in t.name:
            assert reach >= R_MIN - 1e-12, t.name


def test_circles_cover_the_seed_ranges():
    sim = {t.name: t.reference for t in trajectory_set("sim").trajectories}
    rates = [abs(r["turns"]) / 15.0 for n, r in sim.items() if n.startswith("circle")]
    rates += [abs(r["segments"][2]["turns"]) / 12.0 for n, r in sim.items()
              if n.startswith("line-circle")]
    radii = [r["radius"] for n, r in sim.items() if n.startswith("circle")]
    radii += [math.hypot(*r["segments"][0]["to"]) for n, r in sim.items()
              if n.startswith("line-circle")]
    # stratified: each 30th of each range holds one circle
    assert min(rates) < 1 / 15 + 0.94 / 30 and max(rates) > 1 - 0.94 / 30
    assert all(1 / 15 - 1e-9 <= f <= 1 + 1e-9 for f in rates)
    width = (R_MAX - R_MIN) / 30
    assert min(radii) < R_MIN + width + 1e-4 and max(radii) > R_MAX - width - 1e-4
    turns = [r["turns"] for n, r in sim.items() if n.startswith("circle")]
    assert sum(t < 0 for t in turns) and sum(t > 0 for t in turns)  # both directions
    line = sim["line-circle-00"]["segments"]
    assert [s["kind"] for s in line] == ["line", "hold", "circle"]
    assert [s["duration"] for s in line] == [2.5, 0.5, 12.0]


def test_the_seed_test_trajectories():
    sim = {t.name: t for t in trajectory_set("sim").trajectories}
    found = {(sim[f"test-circle-0{k}"].reference["radius"],
              round(abs(sim[f"test-circle-0{k}"].reference["turns"]) / 15.0, 4)) for k in range(3)}
    assert found == {(0.01, 0.93), (0.043, 0.367), (0.02761, 0.632)}
    assert all(t.split == "test" for n, t in sim.items() if n.startswith("test-"))
    hardware = {t.name: t.reference for t in trajectory_set("hardware").trajectories}
    rates = sorted(round(abs(hardware[f"test-circle-0{k}"]["segments"][2]["turns"]) / 75.0, 4)
                   for k in range(6))
    assert rates == [0.066, 0.08, 0.09, 0.106, 0.265, 0.28]


def test_hardware_protocol():
    for t in trajectory_set("hardware").trajectories:
        segments = t.reference["segments"]
        assert t.reference["start"] == [0.0, 0.0]
        assert [s["kind"] for s in segments[:2]] + [segments[-1]["kind"]] == \
            ["line", "hold", "hold"]
        assert (segments[0]["duration"], segments[1]["duration"], segments[-1]["duration"]) == \
            (21.0, 1.0, 3.0)
        motion = segments[2:-1]
        assert sum(s["duration"] for s in motion) == pytest.approx(75.0)
        assert {s["kind"] for s in motion} == ({"circle"} if "circle" in t.name else {"spline"})
        if "circle" in t.name:
            assert 1.0 <= abs(motion[0]["turns"]) <= 22.0


@pytest.mark.parametrize("name", ["sim", "hardware"])
def test_more_draws_add_training_trajectories_and_keep_the_set(name):
    one, three = trajectory_set(name), trajectory_set(name, 3)
    drawn = {t.name: t for t in three.trajectories}
    assert all(drawn[t.name] == t for t in one.trajectories)  # the set itself, unchanged
    extra = [t for t in three.trajectories if t.name not in {u.name for u in one.trajectories}]
    train = [t for t in one.trajectories if t.split == "train"]
    assert [t.name for t in extra] == [f"{t.name}-draw{j}" for j in (1, 2) for t in train]
    assert all(t.split == "train" for t in extra)
    references = [json.dumps(t.reference, sort_keys=True) for t in three.trajectories]
    assert len(set(references)) == len(references)  # new motion, not repeats
    assert len({t.seed for t in three.trajectories}) == len(three.trajectories)
    assert trajectory_set(name, 3) == three


@pytest.mark.parametrize("draws", [0, -1, 1.5, True])
def test_draws_are_a_whole_number_of_at_least_one(draws):
    with pytest.raises(ValueError, match="draws must be a whole number of at least 1"):
        trajectory_set("sim", draws)


def test_unknown_set():
    with pytest.raises(ValueError, match="unknown trajectory set 'lab'"):
        trajectory_set("lab")


def test_r_max_is_what_the_motors_hold_at_rest(nominal):
    """Why R_MAX: at rest the flexures pull the wrist back; the allocated current that holds it
    at R_MAX stays well below the current limit in every direction, and even at the workspace
    edge it does not reach the limit."""
    params = nominal.parameter_values()
    force, pos = ca.SX.sym("f", 2), ca.SX.sym("p", 2)
    currents = ca.Function("i", [force, pos], [motor_currents(force, pos)])

    def holding_current(radius):
        worst = 0.0
        for angle in np.linspace(0.0, 2 * math.pi, 145):
            p = [radius * math.cos(angle), radius * math.sin(angle)]
            f = nominal.inverse_dynamics(p, [0.0, 0.0], [0.0, 0.0], params)
            worst = max(worst, float(np.abs(np.array(currents(f, p))).max()))
        return worst

    i_max = float(PlantModel("nominal").variant.parameters.i_max)
    assert holding_current(R_MAX) < 0.8 * i_max
    assert holding_current(0.05) < 0.9 * i_max
    assert T.SPLINE_POINT_RADIUS < R_MAX
