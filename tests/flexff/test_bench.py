"""flexff.bench's figures that a test can check in seconds (the whole bench runs in
tests/flexff/test_cli.py)."""

import pyarrow.parquet as pq

from flexff.bench import recording_benchmark


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
