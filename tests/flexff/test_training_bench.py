"""flexff bench --training: one timed run in a process of its own, a failed run kept as its
error, the estimate of a whole evaluation's training (the GPU figures themselves come from a
GPU machine: docs/results/training)."""

import pytest

from flexff.learning.evaluate import ENVIRONMENTS, MODELS, trained_scenarios
from flexff.learning.synthetic import synthetic_dataset
from flexff.training_bench import _estimate, _ratios, _timed_as, _timed_run

pytestmark = pytest.mark.learn
TINY = {"channels": 8, "levels": 2}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return synthetic_dataset(tmp_path_factory.mktemp("tiny") / "data", n_train=3, n_test=1,
                             duration=4.0, rate_hz=100.0, seed=3)


def test_a_timed_run_gives_its_start_and_seconds_per_epoch(data, tmp_path):
    run = _timed_run("tcn", "fast", data, tmp_path / "run", "cpu", "float32", 3, TINY)
    assert run["epochs_timed"] == 3
    assert 0 < run["epoch_s"] < run["start_s"] < 60  # the start holds imports and data
    assert run["gpu_busy"] is None and run["gpu_memory_gb"] is None
    assert run["val"] > 0 and run["device"] == "cpu"


def test_a_run_on_the_cpu_trains_there_where_cuda_is_available(data, tmp_path, monkeypatch):
    """The CPU's figures are the CPU's: a run asked for on the CPU does not take the default
    device, which is CUDA wherever a GPU is (the bench's CPU runs trained on the GPU so)."""
    import torch

    from flexff.training_bench import _child

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    child = _child({"kind": "tcn", "preset": "fast", "data": str(data),
                    "out": str(tmp_path / "run"), "device": "cpu", "precision": "float32",
                    "overrides": {**TINY, "epochs": 1}})
    assert child["device"] == "cpu" and not child["cuda_graphs"]


def test_a_failed_run_is_kept_as_its_error(data, tmp_path):
    run = _timed_run("tcn", "fast", data, tmp_path / "run", "cpu", "float32", 1,
                     {**TINY, "channels": -1})
    assert set(run) == {"error"} and run["error"]


def test_the_estimate_adds_each_runs_epochs_and_members_and_divides_by_its_sharing():
    entries = {"tcn": {"epochs": 100, "members": 1,
                       "cpu": {"start_s": 5.0, "epoch_s": 2.0},
                       "cuda": {"start_s": 3.0, "epoch_s": 0.1}},
               "pgnn": {"epochs": 10, "members": 5,
                        "cpu": {"start_s": 5.0, "epoch_s": 1.0},
                        "cuda": {"start_s": 3.0, "epoch_s": 0.5},
                        "cuda_graphs": {"start_s": 3.0, "epoch_s": 0.25}}}
    sharing = {"cuda": {"speedup": {"1": 1.0, "4": 2.5}},
               "cuda_graphs": {"speedup": {"1": 1.0, "4": 2.0}}}
    assert _estimate(entries, sharing) == {
        "cpu_one_after_another": 205.0 + 5 * 15.0,
        "cuda_one_after_another": 13.0 + 5 * 8.0,
        "cuda_shared": (13.0 + 5 * 8.0) / 2.5}  # the TCN's graphs were not timed
    entries["tcn"]["cuda_graphs"] = {"start_s": 3.0, "epoch_s": 0.05}
    assert _estimate(entries, sharing)["cuda_graphs_shared"] == (8.0 + 5 * 5.5) / 2.0
    entries["tcn"]["cuda"] = {"error": "out of memory"}
    assert "cuda_one_after_another" not in _estimate(entries, sharing)
    assert "cuda_graphs_one_after_another" in _estimate(entries, sharing)


def test_the_bound_divides_the_cpus_epoch_by_the_gpus_busy_seconds():
    entry = {"cpu": {"epoch_s": 2.0}, "cuda": {"epoch_s": 1.0, "gpu_busy": 0.25},
             "cuda_graphs": {"epoch_s": 0.5}}
    assert _ratios(entry) == {"speedup": 2.0, "speedup_bound": 8.0, "graph_speedup": 2.0}
    assert _ratios({"cpu": {"epoch_s": 2.0}, "cuda": {"error": "out of memory"}}) == {}


@pytest.mark.parametrize("preset, borrowed", [("thesis", {"pgnn-ilc": "pgnn"}), ("fast", {})])
def test_the_bench_times_what_the_evaluation_trains_and_each_kind_of_work_once(preset,
                                                                               borrowed):
    hardware = ENVIRONMENTS["hardware"]
    scenarios = trained_scenarios(hardware, preset, MODELS,
                                  ilc_labels=hardware.ilc_labelled(MODELS))
    assert [s.name for s in scenarios] == [*MODELS, "pgnn-ilc"]
    timed_as = _timed_as(preset, scenarios)
    # on ILC labels the thesis preset trains pgnn's network on as many samples; the fast
    # preset samples them at 25 Hz, pgnn at 100 Hz
    assert {name: other for name, other in timed_as.items() if name != other} == borrowed
    faster = trained_scenarios(hardware, preset, ["pgnn"], ilc_labels=["pgnn"],
                               extra={"model_rate_hz": 50.0})
    assert len(set(_timed_as(preset, faster).values())) == 1


def test_a_set_no_training_can_run_on_is_one_line_and_exit_code_2(tmp_path, capsys):
    from flexff.cli import main

    tiny = synthetic_dataset(tmp_path / "tiny", n_train=2, n_test=1, duration=2.0,
                             rate_hz=100.0)  # too short to hold out validation windows
    assert main(["bench", "--training", str(tiny), "--preset", "fast", "-o",
                 str(tmp_path / "bench.json")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[-1].startswith(f"flexff: error: {tiny}: no training ran here: ")
    assert "too few to hold out" in lines[-1]
