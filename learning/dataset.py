"""Datasets on disk: a folder with `manifest.json` and one `.npz` of signals per trajectory.

The format is the contract between data collection (co-simulation or hardware logs) and
training. Reading checks everything a training run relies on, so that a bad folder fails at
once with a message naming the file and the signal, and saying what to do about it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from controllers.features import REFERENCE_SIGNALS

FORMAT = "flexff-dataset"
VERSION = 1
MANIFEST = "manifest.json"
SETS = ("sim", "hardware")
SPLITS = ("train", "test")
ENCODER_SIGNALS = ("theta_s1", "theta_s2", "theta_s3")
POSITION_SIGNALS = ("x", "y")
LABEL_SIGNALS = ("Fx", "Fy")
SIGNALS = ("time",) + REFERENCE_SIGNALS + ENCODER_SIGNALS + POSITION_SIGNALS + LABEL_SIGNALS
RECOLLECT = "collect the data again with this flexff version: flexff data collect ..."


class DatasetError(ValueError):
    """A dataset folder that cannot be used; the message says which file and what to do."""


@dataclass(frozen=True)
class Trajectory:
    """One recorded run: its manifest entry and its signals (float64 arrays of equal length)."""

    name: str
    split: str
    signals: Mapping[str, np.ndarray]
    reference: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0

    def __len__(self) -> int:
        return len(self.signals["time"])


@dataclass(frozen=True)
class Dataset:
    """A loaded dataset folder."""

    path: Path
    set: str
    sample_rate_hz: float
    plant: Mapping[str, Any]
    trajectories: tuple[Trajectory, ...]

    def split(self, name: str) -> list[Trajectory]:
        """The trajectories of split `name` ('train' or 'test'), in manifest order."""
        return [t for t in self.trajectories if t.split == name]


def load_dataset(path: str | Path) -> Dataset:
    """Read and check a dataset folder; raise DatasetError saying what is wrong and what to do."""
    path = Path(path)
    manifest_path = path / MANIFEST
    if not manifest_path.is_file():
        raise DatasetError(f"{path} is not a flexff dataset: {MANIFEST} is missing ({RECOLLECT})")
    try:
        manifest = json.loads(manifest_path.read_text())
    except json.JSONDecodeError as err:
        raise DatasetError(f"{manifest_path} is not valid JSON ({err}); {RECOLLECT}") from None
    _check_manifest(manifest, manifest_path)
    rate = float(manifest["sample_rate_hz"])
    trajectories = tuple(_load_trajectory(path, entry, rate) for entry in manifest["trajectories"])
    return Dataset(path=path, set=manifest["set"], sample_rate_hz=rate,
                   plant=manifest.get("plant", {}), trajectories=trajectories)


def write_dataset(path: str | Path, set_name: str, sample_rate_hz: float, plant: Mapping[str, Any],
                  trajectories: list[Trajectory]) -> Path:
    """Write trajectories as a dataset folder (manifest plus one .npz each); returns the folder.

    The one writer of the format: data collection and the synthetic generator both use it, so
    what they write is what `load_dataset` accepts.
    """
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    entries = []
    for traj in trajectories:
        missing = [s for s in SIGNALS if s not in traj.signals]
        if missing:
            raise DatasetError(f"trajectory {traj.name!r} lacks signals {missing}")
        filename = f"{traj.name}.npz"
        np.savez(path / filename, **{s: np.asarray(traj.signals[s], dtype=np.float64)
                                     for s in SIGNALS})
        entries.append({"name": traj.name, "split": traj.split, "file": filename,
                        "reference": dict(traj.reference), "seed": int(traj.seed)})
    manifest = {"format": FORMAT, "version": VERSION, "set": set_name,
                "sample_rate_hz": sample_rate_hz, "plant": dict(plant), "trajectories": entries}
    _check_manifest(manifest, path / MANIFEST)
    (path / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
    return path


def _check_manifest(manifest: Any, where: Path) -> None:
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        found = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        raise DatasetError(f"{where}: format is {found!r}, expected {FORMAT!r}; {RECOLLECT}")
    if manifest.get("version") != VERSION:
        raise DatasetError(f"{where}: dataset version {manifest.get('version')!r}, this flexff "
                           f"reads version {VERSION}; {RECOLLECT}")
    if manifest.get("set") not in SETS:
        raise DatasetError(f"{where}: 'set' is {manifest.get('set')!r}, expected one of {SETS}")
    rate = manifest.get("sample_rate_hz")
    if not isinstance(rate, (int, float)) or not np.isfinite(rate) or rate <= 0:
        raise DatasetError(f"{where}: 'sample_rate_hz' must be a positive number, got {rate!r}")
    entries = manifest.get("trajectories")
    if not isinstance(entries, list) or not entries:
        raise DatasetError(f"{where}: no trajectories listed; {RECOLLECT}")
    names = set()
    for k, entry in enumerate(entries):
        if not isinstance(entry, dict) or not {"name", "split", "file"} <= set(entry):
            raise DatasetError(f"{where}: trajectory entry {k} needs 'name', 'split' and 'file'")
        if entry["split"] not in SPLITS:
            raise DatasetError(f"{where}: trajectory {entry['name']!r} has split "
                               f"{entry['split']!r}, expected one of {SPLITS}")
        if entry["name"] in names:
            raise DatasetError(f"{where}: trajectory name {entry['name']!r} appears twice")
        names.add(entry["name"])


def _load_trajectory(folder: Path, entry: Mapping[str, Any], rate: float) -> Trajectory:
    file = folder / entry["file"]
    if not file.is_file():
        raise DatasetError(f"{file} is listed in {MANIFEST} but missing; {RECOLLECT}")
    with np.load(file) as npz:
        missing = [s for s in SIGNALS if s not in npz.files]
        if missing:
            raise DatasetError(f"{file} lacks signals {missing}; {RECOLLECT}")
        signals = {s: np.asarray(npz[s], dtype=np.float64) for s in SIGNALS}
    lengths = {s: a.shape for s, a in signals.items()}
    if any(a.ndim != 1 for a in signals.values()) or len(set(lengths.values())) != 1:
        raise DatasetError(f"{file}: signals must be 1-D arrays of equal length, got {lengths}; "
                           f"{RECOLLECT}")
    for s, a in signals.items():
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise DatasetError(f"{file}: signal {s!r} has {bad.size} NaN/Inf value(s), first at "
                               f"sample {bad[0]}; fix or drop this trajectory, or {RECOLLECT}")
    steps = np.diff(signals["time"])
    if steps.size == 0 or not np.allclose(steps, 1.0 / rate, rtol=1e-6, atol=1e-9):
        raise DatasetError(f"{file}: 'time' must be sampled at the manifest's {rate:g} Hz "
                           f"(steps of {1.0 / rate:g} s); {RECOLLECT}")
    return Trajectory(name=entry["name"], split=entry["split"], signals=signals,
                      reference=entry.get("reference", {}), seed=int(entry.get("seed", 0)))
