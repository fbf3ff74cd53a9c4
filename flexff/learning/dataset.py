"""Datasets on disk: a folder with `manifest.json` and one `.npz` of signals per trajectory.

The format is the contract between data collection (co-simulation or logs) and training.
Reading checks everything training relies on, so a bad folder fails at once naming the file
and the signal. The manifest holds each file's sha256 and its own; version 3 adds the motor
currents; an entry's `derived` names signals computed rather than measured, which training
refuses for the signals it reads (TRAINED).

Docs: "File formats", section A dataset folder (docs/reference/file-formats.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexff.fmu.cache import file_sha256

# `X as X`: other modules import FORMAT, MANIFEST, DatasetError and Trajectory from here
from flexff.learning.dataset_files import (
    FORMAT as FORMAT,
)
from flexff.learning.dataset_files import (
    MACHINE_VERSION,
    MANIPULATOR_VERSIONS,
    check_arrays,
    check_entries,
    digest,
    is_sha256,
    read_arrays,
    read_manifest,
    save_arrays,
    save_manifest,
)
from flexff.learning.dataset_files import (
    MANIFEST as MANIFEST,
)
from flexff.learning.dataset_files import (
    DatasetError as DatasetError,
)
from flexff.learning.dataset_files import (
    Trajectory as Trajectory,
)
from flexff.plant.signals import CURRENTS, ENCODERS, FORCES, REFERENCE, TRUE_POSITION, names

READS = MANIPULATOR_VERSIONS  # the versions load_dataset reads (module doc)
VERSION = READS[-1]
COLLECTED = "flexff data collect"  # the manifest's `source` for a collected set
IMPORTED = "flexff data import"  # ... and for imported logs
WRITTEN = "learning.dataset.write_dataset"
SETS = ("sim", "hardware")
# a trajectory's columns (plant.signals): reference, encoders, true position, force labels
REFERENCE_SIGNALS = names(REFERENCE)
ENCODER_SIGNALS = names(ENCODERS)
POSITION_SIGNALS = names(TRUE_POSITION)
LABEL_SIGNALS = names(FORCES)
SIGNALS = ("time", *REFERENCE_SIGNALS, *ENCODER_SIGNALS, *POSITION_SIGNALS, *LABEL_SIGNALS)
CURRENT_SIGNALS = names(CURRENTS)  # optional columns (module doc): a current-level model's labels
TRAINED = ("time", *ENCODER_SIGNALS, *LABEL_SIGNALS)  # what training reads (learning.features)
RECOLLECT = "collect the data again with this flexff version: flexff data collect ..."


@dataclass(frozen=True)
class Dataset:
    """A loaded dataset folder."""

    path: Path
    set: str
    sample_rate_hz: float
    plant: Mapping[str, Any]
    trajectories: tuple[Trajectory, ...]
    digest: str  # sha256 of the whole manifest, splits included: what a run trained on

    def split(self, name: str) -> list[Trajectory]:
        """The trajectories of split `name` ('train' or 'test'), in manifest order."""
        return [t for t in self.trajectories if t.split == name]


def load_dataset(path: str | Path) -> Dataset:
    """Read and check a dataset folder; raise DatasetError saying what is wrong and what to do."""
    path = Path(path)
    manifest_path, manifest = read_manifest(path, RECOLLECT)
    _check_manifest(manifest, manifest_path)
    source = manifest.get("source")
    if manifest["sha256"] != digest(manifest, splits=False):
        redo = {COLLECTED: f"run flexff data collect into {path} again with the set it was "
                           f"collected with",
                IMPORTED: "import the logs again"}.get(source, "write the dataset again")
        raise DatasetError(f"{manifest_path} was edited: its set, sample rate, plant or "
                           f"trajectory list no longer match its sha256 (only a trajectory's "
                           f"'split' may be changed by hand): undo the edit, or {redo}")
    fix = {COLLECTED: f"run flexff data collect --set {manifest['set']} -o {path} again to "
                      f"re-run it",
           IMPORTED: "import the logs again (flexff data import)"}.get(
        source, f"write the dataset again, or {RECOLLECT}")
    rate_hz = float(manifest["sample_rate_hz"])
    trajectories = tuple(_load_trajectory(path, entry, rate_hz, fix)
                         for entry in manifest["trajectories"])
    return Dataset(path=path, set=manifest["set"], sample_rate_hz=rate_hz,
                   plant=manifest.get("plant", {}), trajectories=trajectories,
                   digest=digest(manifest, splits=True))


def write_dataset(path: str | Path, set_name: str, sample_rate_hz: float, plant: Mapping[str, Any],
                  trajectories: list[Trajectory]) -> Path:
    """Write trajectories as a dataset folder (one .npz each, then the manifest); return it.

    Data collection writes its files itself (in parallel workers) and its manifest with
    `write_manifest`, as this does, so what either writes is what `load_dataset` accepts.
    """
    path = Path(path)
    entries = []
    for traj in trajectories:
        missing = [s for s in SIGNALS if s not in traj.signals]
        if missing:
            raise DatasetError(f"trajectory {traj.name!r} lacks signals {missing}")
        filename = f"{traj.name}.npz"
        save_signals(path / filename, traj.signals)
        entries.append({"name": traj.name, "split": traj.split, "file": filename,
                        "reference": dict(traj.reference), "seed": int(traj.seed)})
    write_manifest(path, set_name, sample_rate_hz, plant, entries, WRITTEN)
    return path


def save_signals(path: Path, signals: Mapping[str, np.ndarray]) -> None:
    """Write one trajectory's SIGNALS (and CURRENT_SIGNALS, where `signals` holds them) as
    float64 arrays to the .npz `path`, atomically."""
    save_arrays(path, {**{s: signals[s] for s in SIGNALS}, **_currents(signals, str(path))})


def write_manifest(path: Path, set_name: str, sample_rate_hz: float, plant: Mapping[str, Any],
                   entries: list[dict[str, Any]], source: str,
                   extra: Mapping[str, Any] | None = None) -> None:
    """Write the manifest of the trajectory files in `path` (entries: name, split, file,
    reference, seed, optionally derived), adding each file's sha256 and the manifest's own;
    `extra` adds top-level entries (a collection's `loop`)."""
    entries = [{**e, "sha256": file_sha256(path / e["file"])} for e in entries]
    manifest = {"format": FORMAT, "version": VERSION, "set": set_name, "source": source,
                "sample_rate_hz": sample_rate_hz, "plant": dict(plant), **(extra or {}),
                "trajectories": entries}
    manifest["sha256"] = digest(manifest, splits=False)
    _check_manifest(manifest, path / MANIFEST)
    save_manifest(path, manifest)


def _check_manifest(manifest: Any, where: Path) -> None:
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        found = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        raise DatasetError(f"{where}: format is {found!r}, expected {FORMAT!r}; {RECOLLECT}")
    if manifest.get("version") == MACHINE_VERSION:
        raise DatasetError(f"{where}: a dataset of version {MACHINE_VERSION} (a machine "
                           f"description's signals), not the manipulator's: read it with "
                           f"learning.machine_dataset.load_machine_dataset")
    if manifest.get("version") not in READS:
        raise DatasetError(f"{where}: dataset version {manifest.get('version')!r}, this flexff "
                           f"reads versions {', '.join(map(str, READS))}; {RECOLLECT}")
    if not is_sha256(manifest.get("sha256")):
        raise DatasetError(f"{where}: 'sha256' is missing or not a sha256; {RECOLLECT}")
    if manifest.get("set") not in SETS:
        raise DatasetError(f"{where}: 'set' is {manifest.get('set')!r}, expected one of {SETS}")
    rate_hz = manifest.get("sample_rate_hz")
    if not isinstance(rate_hz, (int, float)) or not np.isfinite(rate_hz) or rate_hz <= 0:
        raise DatasetError(f"{where}: 'sample_rate_hz' must be a positive number, got {rate_hz!r}")
    check_entries(manifest.get("trajectories"), where, RECOLLECT)
    for entry in manifest["trajectories"]:
        trained = [s for s in TRAINED if s in entry.get("derived", {})]
        if trained:
            raise DatasetError(f"{where}: trajectory {entry['name']!r}: {', '.join(trained)} "
                               f"marked derived, but training reads them as measured: they "
                               f"must come from the logs")


def _load_trajectory(folder: Path, entry: Mapping[str, Any], rate_hz: float,
                     fix: str) -> Trajectory:
    file = folder / entry["file"]
    signals = read_arrays(folder, entry, (*SIGNALS, *CURRENT_SIGNALS), fix)
    missing = [s for s in SIGNALS if s not in signals]
    if missing:
        raise DatasetError(f"{file} lacks signals {missing}; {fix}")
    try:
        _currents(signals, str(file))
    except ValueError as error:
        raise DatasetError(f"{error}; {fix}") from None
    check_arrays(file, signals, rate_hz, fix)
    return Trajectory(name=entry["name"], split=entry["split"], signals=signals,
                      reference=entry.get("reference", {}), seed=int(entry.get("seed", 0)),
                      derived=entry.get("derived", {}))


def _currents(signals: Mapping[str, Any], where: str) -> dict[str, np.ndarray]:
    """The CURRENT_SIGNALS of `signals` as float64 arrays: all three, or none."""
    present = [s for s in CURRENT_SIGNALS if s in signals]
    if present and len(present) != len(CURRENT_SIGNALS):
        raise ValueError(f"{where} holds {', '.join(present)} but not all of "
                         f"{', '.join(CURRENT_SIGNALS)}")
    return {s: np.asarray(signals[s], dtype=np.float64) for s in present}
