"""Collection on a stranger's 3-axis loop (tests.array_plant): FMI array names in the
description, `feedthrough = false`, and a [record] list that names none of the signals a
dataset needs: the run records them all the same."""

import numpy as np

from flexff.cosim.config import load_config
from flexff.learning.machine_collect import collect_machine
from tests.array_plant import build_array_plant
from tests.cosim.test_stranger_plant import AXIS_NAMES, loop_config


def test_a_loop_recording_a_few_signals_still_collects_its_dataset(tmp_path):
    build_array_plant(tmp_path)
    (tmp_path / "run.toml").write_text(loop_config(False))
    loop = load_config(tmp_path / "run.toml")
    assert "vr_ref" not in loop.record.signals and "pid.r_effort" not in loop.record.signals
    data = collect_machine(loop, tmp_path / "data", 1, 1, 1.0, workers=1, progress=False)
    assert len(data.trajectories) == 2
    for trajectory in data.trajectories:
        for axis in AXIS_NAMES:
            for name in (f"{axis}_ref", f"v{axis}_ref", f"{axis}_measured", f"{axis}_effort"):
                assert np.all(np.isfinite(trajectory.signals[name])), name
        assert np.ptp(trajectory.signals["r_measured"]) > 0  # pos[1], read by its FMI name
