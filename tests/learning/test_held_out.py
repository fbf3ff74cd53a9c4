"""The held-out references (learning.held_out): which test trajectories a run can replay, and
the runs on them."""

import numpy as np
import pytest

from flexff.cosim.config import parse_config
from flexff.cosim.scenario import reference_signals
from flexff.learning.dataset import REFERENCE_SIGNALS, load_dataset
from flexff.learning.held_out import BASE, references_held_out, run_held_out
from flexff.learning.synthetic import synthetic_dataset


def test_a_circles_reference_replays_its_motion_and_a_spline_is_left_out(tmp_path):
    """A synthetic set's circle carries the [reference] table of its own motion (a run on it
    reproduces the recorded reference); its splines carry a description a run cannot take."""
    data = load_dataset(synthetic_dataset(tmp_path / "data", n_train=0, n_test=6, duration=2.0,
                                          rate_hz=1000.0, seed=5))
    runnable, other = references_held_out(data)
    kinds = {t.name: t.reference["kind"] for t in data.split("test")}
    assert sorted(runnable) == sorted(n for n, k in kinds.items() if k == "circle")
    assert sorted(other) == sorted(n for n, k in kinds.items() if k == "spline")
    assert runnable and other
    for trajectory in data.split("test"):
        if trajectory.name in runnable:
            config = parse_config({"run": {"stop": 2.0}, "reference": dict(trajectory.reference)})
            replayed = reference_signals(config)
            for signal in REFERENCE_SIGNALS:
                recorded = trajectory.signals[signal]  # t = 0 .. 2 s less a sample
                assert np.allclose(replayed[signal][:recorded.size], recorded, atol=1e-12)


def test_the_runs_go_side_by_side_and_a_failed_one_is_raised(tmp_path):
    config = parse_config({"run": {"stop": 0.2}, "reference": {"kind": "thesis-eval"}},
                          name="short")
    configs = {f"ref{k}": {BASE: config, "again": config} for k in range(3)}
    result = run_held_out(configs, tmp_path / "ok", progress=False, workers=2)
    assert result["references"] == ["ref0", "ref1", "ref2"]  # in the order given
    assert result["e2_ratio"]["again"] == {"x": [1.0] * 3, "y": [1.0] * 3}  # deterministic
    assert sorted(p.name for p in (tmp_path / "ok" / "ref1").iterdir()) == ["again", "pid"]
    (tmp_path / "blocked").mkdir()
    (tmp_path / "blocked" / "ref0").write_text("a file where the run's folder goes")
    with pytest.raises(Exception, match="ref0"):
        run_held_out(configs, tmp_path / "blocked", progress=False, workers=2)
