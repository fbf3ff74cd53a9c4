"""A run folder's results, read one way: `flexff.results.load(DIR)` for what `flexff run`,
`api.run` or a batch wrote (the record, in Parquet or an earlier version's .npz, as
cosim.recording reads it; metrics.json; run.json), and `export_csv(DIR)` for a CSV copy of the
record (`flexff results export DIR`). A record the run did not finish, killed or stopped, is
partial: `RunResult.partial` and export_csv's warning say so.

    from flexff import results

    result = results.load("out")
    result.recording["vdp.x0"], result.recording.time, result.metrics["wall_s"]
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flexff.cosim.config import RECORDED
from flexff.cosim.recording import PARQUET_NAME, PARTS_NAME, Recording, load_recording
from flexff.cosim.recording import export_csv as _export_csv
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

    @property
    def partial(self) -> str | None:
        """Why the record ends before the run's end (None: it does not, as far as the folder
        says; an earlier version's run.json does not say)."""
        return _partial(self.folder, self.configuration)


def load(folder: str | Path) -> RunResult:
    """The results of a run in `folder` (a killed run's record up to its last chunk, with
    empty metrics and configuration where it wrote none).

    >>> result = api.read("out")
    >>> result.metrics == metrics
    True"""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder (give the -o folder of flexff run)")
    return RunResult(folder, load_recording(folder), _json(folder / "metrics.json"),
                     _json(folder / "run.json"))


def export_csv(folder: str | Path) -> Path:
    """Write signals.csv beside the record in `folder` (cosim.recording.export_csv) and return
    its path; warn where the record is partial (RunResult.partial)."""
    path = _export_csv(folder)
    why = _partial(Path(folder), _json(Path(folder) / "run.json"))
    if why is not None:
        warnings.warn(f"{folder}: a partial record: {why}", stacklevel=2)
    return path


def _partial(folder: Path, configuration: dict[str, Any]) -> str | None:
    recorded = configuration.get(RECORDED) or {}
    if recorded.get("complete") is True:  # joined or not (a disk that filled at the join)
        return None
    if (folder / PARTS_NAME).is_dir() and not (folder / PARQUET_NAME).is_file():
        return (f"the run did not end normally (it was killed, or its disk was full): its "
                f"record is the chunks in {PARTS_NAME}/ up to the last one written")
    if recorded.get("complete") is False:
        end = recorded.get("last_time")
        return ("the run stopped before it recorded a point" if end is None else
                f"the run stopped early; its record holds {recorded.get('points')} points up "
                f"to t = {end:.9g} s")
    return None


def _json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    data: dict[str, Any] = json.loads(path.read_text())
    return data
