"""Tracking metrics for any machine's axes: expressions of recorded signals, streamed or whole."""

import numpy as np
import pytest

from flexff.cosim.machine import parse_machine
from flexff.cosim.metrics import Tracking, error_norms, machine_axes, run_metrics, tracking_metrics
from flexff.cosim.recording import Recording


def recording() -> Recording:
    time = np.arange(0.0, 2.0, 1e-3)
    rng = np.random.default_rng(3)
    signals = {"ref.q1_ref": np.sin(time), "enc.a": np.sin(time) + rng.normal(0, 1e-3, time.size),
               "enc.b": np.sin(time) + rng.normal(0, 1e-3, time.size),
               "ref.z_ref": 0.1 * time, "plant.z": 0.1 * time - 1e-4,
               "plant.z_true": 0.1 * time - 2e-4}
    return Recording(time, signals)


def two_axes():
    axis = {"feedforward": "c.ff", "effort": "c.u", "range": [-1, 1], "velocity": 1.0,
            "acceleration": 1.0}
    return parse_machine({"axis": [{**axis, "name": "q1", "measured": "0.5 * (enc.a + enc.b)"},
                                   {**axis, "name": "z", "measured": "plant.z",
                                    "true": "plant.z_true"}]}, "m.toml")


def test_each_axis_compares_its_reference_with_its_kinematic_map_or_true_position():
    record = recording()
    metrics = tracking_metrics(record, machine_axes(two_axes()))
    q1_error = record["q1_ref"] - 0.5 * (record["enc.a"] + record["enc.b"])
    assert metrics["q1"] == error_norms(q1_error, record.step)
    assert metrics["z"]["einf"] == pytest.approx(2e-4)  # the true position, not the measured
    assert set(run_metrics(record, machine_axes(two_axes()))) >= {"q1", "z", "wall_s"}


def test_streamed_chunks_give_the_same_metrics():
    record, axes = recording(), machine_axes(two_axes())
    tracking = Tracking(tuple(record.signals), record.step, axes)
    for chunk in np.array_split(np.arange(record.time.size), 7):
        tracking.add({n: v[chunk] for n, v in record.signals.items()})
    whole = tracking_metrics(record, axes)
    for axis, norms in tracking.metrics().items():
        assert norms == pytest.approx(whole[axis], rel=1e-12)


def test_a_record_without_an_axis_signal_is_not_tracked():
    record = recording()
    record = Recording(record.time, {n: v for n, v in record.signals.items() if n != "enc.b"})
    assert not Tracking.tracks(tuple(record.signals), machine_axes(two_axes()))
    assert "q1" not in run_metrics(record, machine_axes(two_axes()))
