"""flexff.bench's figures that a test can check in seconds (the whole bench runs in
tests/flexff/test_cli.py)."""

import pyarrow.parquet as pq

from flexff.bench import network_call_table, recording_benchmark


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
