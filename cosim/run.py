"""run_config: one configured run, from TOML to a folder of results.

The folder gets signals.npz (and signals.csv, see cosim.recording), metrics.json
(cosim.metrics; with a learned feedforward also `feedforward_range`, where the reference
leaves the model's training range), path.png, error.png, forces.png (cosim.plots) and
run.json, the checked configuration as plain data. The FMUs are built into the fmu/ cache
and loaded from a temporary copy.
"""

from __future__ import annotations

import dataclasses
import json
import tempfile
from pathlib import Path

from controllers.training_range import MARGIN, training_range_excess
from cosim.config import RunConfig, load_config
from cosim.master import Master
from cosim.metrics import run_metrics
from cosim.plots import SIGNALS as PLOT_SIGNALS
from cosim.plots import write_plots
from cosim.recording import Recording, atomic_write, save_recording
from cosim.scenario import build_slaves, reference_samples, source_signals


def simulate_config(config: RunConfig, progress: bool | None = None) -> Recording:
    """Run a configuration; the recording holds its [record] signals plus those the metrics
    and plots need."""
    wanted = list(config.record.signals) if config.record.signals is not None else None
    with tempfile.TemporaryDirectory(prefix="flexff-fmus-") as folder:
        slaves = build_slaves(config, folder)
        sources = source_signals(config)
        with Master(slaves, list(sources), config.step) as master:
            record = None if wanted is None else wanted + [
                n for n in PLOT_SIGNALS if n not in wanted]
            return master.run(sources, config.steps, record, progress)


def feedforward_range(config: RunConfig) -> dict | None:
    """Where the reference of a learned-feedforward run leaves the model's training range
    (controllers.training_range): {"margin", "outside": [features, farthest first]}, or None
    for a model exported without its range."""
    reference = reference_samples(config.reference.build(config.step), config.steps)
    excess = training_range_excess(config.feedforward.model, reference, config.step)
    if excess is None:
        return None
    return {"margin": MARGIN, "outside": [dataclasses.asdict(e) for e in excess]}


def range_warning(metrics: dict) -> str | None:
    """A line saying the learned feedforward extrapolates in this run, or None."""
    outside = (metrics.get("feedforward_range") or {}).get("outside")
    if not outside:
        return None
    worst = outside[0]
    return (f"warning: the reference leaves the learned model's training range in "
            f"{len(outside)} features (worst: {worst['signal']}, {worst['spans']:.2g} spans "
            f"beyond): the feedforward extrapolates; train on motion like this reference")


def _write_json(path: Path, data: dict) -> None:
    text = json.dumps(data, indent=2, default=str) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text))


def run_config(config: RunConfig | str | Path, output_dir: str | Path,
               progress: bool | None = None) -> dict:
    """Run one configuration (or the TOML file at that path) into `output_dir`; return the
    metrics written to metrics.json."""
    if not isinstance(config, RunConfig):
        config = load_config(config)
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    recording = simulate_config(config, progress)
    metrics = run_metrics(recording)
    if config.feedforward.kind == "onnx":
        metrics["feedforward_range"] = feedforward_range(config)
    kept = recording.signals if config.record.signals is None else {
        n: recording[n] for n in config.record.signals}
    save_recording(Recording(recording.time, kept), out, csv=config.record.csv)
    write_plots(recording, out)
    _write_json(out / "run.json", dataclasses.asdict(config))
    _write_json(out / "metrics.json", metrics)
    return metrics
