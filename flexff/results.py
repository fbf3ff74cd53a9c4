"""A run folder's results, read one way: `flexff.results.load(DIR)` for what `flexff run`,
`api.run` or a batch wrote (the record, in Parquet or an earlier version's .npz, as
cosim.recording reads it; metrics.json; run.json), and `export_csv(DIR)` for a CSV copy of the
record (`flexff results export DIR`).

    from flexff import results

    result = results.load("out")
    result.recording["vdp.x0"], result.recording.time, result.metrics["wall_s"]
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flexff.cosim.recording import Recording, export_csv, load_recording
from flexff.fmu.errors import InputError

__all__ = ["RunResult", "export_csv", "load"]


@dataclass(frozen=True)
class RunResult:
    """What `flexff run` wrote into a folder: the recording, metrics.json and run.json (the
    checked configuration in the general form)."""

    folder: Path
    recording: Recording
    metrics: dict[str, Any]
    configuration: dict[str, Any]


def load(folder: str | Path) -> RunResult:
    """The results of a run in `folder` (a killed run's record up to its last chunk, with
    empty metrics and configuration where it wrote none)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder (give the -o folder of flexff run)")
    return RunResult(folder, load_recording(folder), _json(folder / "metrics.json"),
                     _json(folder / "run.json"))


def _json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    data: dict[str, Any] = json.loads(path.read_text())
    return data
