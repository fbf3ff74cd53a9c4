"""The stranger-like 3-axis plant (tests.stranger3_plant) under PID alone: its loop runs as
written, every axis tracks, and the lift holds its mass against gravity."""

import numpy as np
import pytest

from flexff.cosim.config import load_config
from flexff.cosim.run import simulate_config
from tests.stranger3_plant import MZ, G, write_loop


def test_the_loop_tracks_and_holds_gravity(tmp_path):
    recording = simulate_config(load_config(write_loop(tmp_path)), progress=False)
    lift = np.asarray(recording["pid.z_effort"])
    at_rest = np.asarray(recording["vz_ref"]) == 0.0
    assert np.median(lift[at_rest]) == pytest.approx(MZ * G, rel=0.05)
    for axis in ("r", "y", "z"):
        error = np.asarray(recording[f"{axis}_ref"]) - np.asarray(recording[f"plant.{axis}_out"])
        assert np.abs(error).max() < 0.01
