"""A collection starts every trajectory where the loop rests (learning.machine_collect): on a
machine resting at 2.9 in its range [2.6, 3.4] (a drive whose encoder the loop reads with an
offset) each trajectory's first samples are the resting position and its effort starts without
a spike; the other axis, resting at its centre, is as before."""

import numpy as np
import pytest

from flexff.cosim.config import parse_config
from flexff.learning.machine_collect import collect_machine, rest_positions

REST = 2.9  # where the drive u rests, in the loop's coordinates
CLASSES = ("moves", "multisine", "sine", "random")


def offset_loop(folder):
    """Two drives under one PID: u read with an offset of 2.9 (range [2.6, 3.4], centre 3.0),
    x at rest at its range's centre."""
    axes = {"u": (REST, [2.6, 3.4]), "x": (0.0, [-0.04, 0.04])}
    return parse_config({
        "run": {"step": 0.001, "stop": 1.0},
        "fmu": {"pid": {"builtin": "pid", "axes": [
            {"name": a, "mass": 2.0, "crossover_hz": 20.0, "effort_limit": 200.0}
            for a in axes]},
            **{f"d{a}": {"builtin": "drive", "parameters": {"cogging": 0.0}} for a in axes}},
        "connection": [c for a, (offset, _) in axes.items() for c in (
            {"from": f"pid.{a}_effort", "to": f"d{a}.F"},
            {"from": f"d{a}.x", "to": f"pid.{a}", "offset": offset})],
        "source": [{"kind": "constant", "values": {f"{a}_ff": 0.0 for a in axes}}],
        "machine": {"name": "offset", "axis": [
            {"name": a, "measured": f"d{a}.x + {offset}", "true": f"d{a}.x_true + {offset}",
             "feedforward": f"pid.{a}_ff", "effort": f"pid.{a}_effort", "range": span,
             "velocity": 0.2, "acceleration": 2.0} for a, (offset, span) in axes.items()]}},
        name="offset", base=folder, origin=str(folder / "offset.toml"))


def test_the_loop_rests_where_its_plant_starts(tmp_path):
    assert rest_positions(offset_loop(tmp_path)) == [pytest.approx(REST), 0.0]


def test_every_trajectory_starts_at_rest_where_the_loop_rests(tmp_path):
    data = collect_machine(offset_loop(tmp_path), tmp_path / "data", len(CLASSES), 0, 3.0,
                           classes=CLASSES, workers=1, progress=False)
    assert len(data.trajectories) == len(CLASSES)
    for trajectory in data.trajectories:
        signals = trajectory.signals
        u, x = signals["u_ref"], signals["x_ref"]
        assert u[0] == pytest.approx(REST) and x[0] == 0.0, trajectory.name
        assert signals["vu_ref"][0] == 0.0 and signals["u_measured"][0] == pytest.approx(REST)
        assert np.abs(np.diff(u)).max() < 1e-3  # a ramp, no step: under 1 m/s between samples
        effort = np.abs(signals["u_effort"])
        # measured: a step of 0.1 m to the centre saturated the effort at 200 N at once; from
        # where it rests the first 20 ms command well under 5 % of the trajectory's peak
        assert effort[:20].max() < 0.05 * effort.max(), trajectory.name
        assert effort.max() < 200.0 * 0.99, trajectory.name  # never at its limit
    settings = (tmp_path / "data" / "collection.json").read_text()
    assert '"starts"' in settings and '"u": 2.9' in settings
