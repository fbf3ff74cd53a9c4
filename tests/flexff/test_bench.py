"""flexff.bench's figures that a test can check in seconds (the whole bench runs in
tests/flexff/test_cli.py)."""

import numpy as np
import pyarrow.parquet as pq
import pytest

from flexff.bench import feedforward_step, network_call_table, realtime_table, recording_benchmark
from flexff.cosim.timing import Pacing, StepTiming


def test_the_recording_benchmark_runs_the_loop_with_its_record_on_and_off(tmp_path):
    """0.2 s of the paced hardware loop with every signal recorded and plotted, then with the
    least record: each run's base-task figures, the medians and the ratios on over off."""
    figures = recording_benchmark(tmp_path, 0.2, pairs=1)
    for mode in ("on", "off"):
        (run,) = figures["runs"][mode]
        assert run["steps"] == 200 and run["overruns"] >= 0
        assert 0 < run["tet_us"]["p50"] <= run["tet_us"]["p99"] <= run["tet_us"]["max"]
        assert figures["median"][mode]["tet_us"] == run["tet_us"]
    on, off = (figures["median"][m]["tet_us"] for m in ("on", "off"))
    assert figures["ratio_on_over_off"] == {"p50": on["p50"] / off["p50"],
                                            "p99": on["p99"] / off["p99"]}
    kept = {mode: pq.read_schema(tmp_path / f"recording-{mode}-0" / "signals.parquet").names
            for mode in ("on", "off")}
    assert kept["off"] == ["time"] and len(kept["on"]) > 30
    assert (tmp_path / "recording-on-0" / "path.png").is_file()
    assert not (tmp_path / "recording-off-0" / "path.png").exists()


def test_the_network_call_table_lines_up_each_model_and_runtime():
    """The bench's text table of the network's time per call: a row per model, with p50 / p99
    and the FMU's size in each runtime, and C over onnxruntime."""
    figures = {"reference": "thesis-eval", "mode": "step", "models": {
        kind: {"c": {"p50_us": 7.94, "p99_us": 12.6, "fmu_bytes": 558255},
               "onnxruntime": {"p50_us": 39.8, "p99_us": 79.4, "fmu_bytes": 13492110},
               "ratio_c_over_onnxruntime": {"p50": 0.2, "p99": 0.158}}
        for kind in ("lstm", "tcn")}}
    title, head, *rows = network_call_table(figures).splitlines()
    assert title == "network time per call (thesis-eval, step mode)"
    assert head.split("  ")[0] == "model" and head.endswith("C / onnxruntime p50 / p99")
    assert len({len(line) for line in (head, *rows)}) == 1  # columns aligned
    for kind, row in zip(("lstm", "tcn"), rows):
        assert row.split() == [kind, "7.94", "/", "12.6", "0.558", "39.8", "/", "79.4", "13.5",
                               "0.2", "/", "0.158"]
    only_c = {**figures, "models": {"lstm": {"c": figures["models"]["lstm"]["c"]}}}
    head, row = network_call_table(only_c).splitlines()[1:]
    assert "onnxruntime" not in head and row.split() == ["lstm", "7.94", "/", "12.6", "0.558"]


def _timing(period: int = 10, steps: int = 100) -> StepTiming:
    """A paced run's timing: the feedforward's share 20 us at its call points (every `period`
    steps from 0), 2 us between them; the plant's 10 us throughout."""
    share = np.where(np.arange(steps) % period == 0, 20e-6, 2e-6)
    fmu_tet = np.column_stack([share, np.full(steps, 10e-6)])
    calls = {"calls": steps // period, "p50": 30.0, "p99": 40.0, "max": 50.0,
             "period_steps": period, "overruns": 1, "handovers": steps // period,
             "computed_in_step": 0, "signalled": 3}
    return StepTiming(1e-3, ("feedforward", "plant"), fmu_tet.sum(axis=1), fmu_tet,
                      np.zeros(steps), Pacing(), 0, 1, (), None,
                      network_calls={"feedforward": calls})


def test_the_feedforward_step_splits_at_the_hand_overs():
    """The steps at the network's call points hand a call over: their share of the TET apart
    from the others', with the task's counts."""
    figures = feedforward_step(_timing())
    assert figures["tet_us"]["handover"]["p50"] == pytest.approx(20.0)
    assert figures["tet_us"]["handover"]["max"] == pytest.approx(20.0)
    assert figures["tet_us"]["no_handover"]["p99"] == pytest.approx(2.0)
    assert figures["p99_over_p50"] == pytest.approx(10.0)  # 10 % of the steps hand over
    assert (figures["handovers"], figures["signalled"], figures["waited_for"],
            figures["computed_in_base_task"]) == (10, 3, 1, 0)


def test_the_realtime_table_lines_up_each_loop():
    """The bench's text summary of its paced loops: a row per loop and runtime, the loop
    without feedforward and the idle loop last, columns aligned."""
    timing = _timing()
    table = timing.table(0.1)
    loop = {"tasks": table["tasks"], "overruns": 3, "feedforward_step": feedforward_step(timing)}
    figures = {"reference": "thesis-hardware-eval", "cpu": 1, "tcn": loop,
               "tcn_onnxruntime": loop, "no_feedforward": {"tasks": table["tasks"], "overruns": 1},
               "idle": {"tet_us": table["tet_us"], "overruns": 2}}
    title, head, *rows = realtime_table(figures).splitlines()
    assert title.startswith("paced at 1 kHz on CPU 1 (thesis-hardware-eval)")
    assert len({len(line) for line in (head, *rows)}) == 1  # columns aligned
    assert [row.split()[0] for row in rows] == ["tcn", "tcn_onnxruntime", "no", "idle"]
    cells = rows[0].split()
    assert cells[6] == "3"  # the overruns, after TET p50 / p99 / max
    assert cells[-8:] == ["10", "10", "/", "3", "/", "1", "/", "0"]  # p99/p50, the counts
