"""Datasets of any machine (version 4): the folder of learning.dataset (manifest.json and one
.npz of float64 signals per trajectory, each file's sha256 and the manifest's own) for the
signals a machine description names.

The manifest holds the description as data (`describe`: the machine's name and, per axis, its
name, units and signal names), so a folder is refused where another description meets it.
Each trajectory holds `time` and Machine.signals: references and their derivatives, measured
positions, efforts. Its entry's `derived` maps a signal its source did not hold to how it was
computed: only references may be derived, never what training reads as measured.
Beside it, `description` keeps the whole description (limits, prior, log map: cosim.machine's
table), which training reads for the features' widths and the prior's terms.
`write_machine_dataset` writes a folder whole or not at all (`flexff data import --machine`,
learning.machine_logs); data collection (learning.machine_collect) writes its trajectories one
by one (`save_trajectory`) and the manifest last. A manipulator folder (version 2 or 3) is
refused here with a pointer to learning.dataset.load_dataset, its reader.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.machine import Machine, machine_table, parse_machine
from flexff.fmu.cache import file_sha256
from flexff.learning.dataset_files import (
    FORMAT,
    MACHINE_VERSION,
    MANIFEST,
    MANIPULATOR_VERSIONS,
    DatasetError,
    Trajectory,
    check_arrays,
    check_entries,
    digest,
    is_sha256,
    read_arrays,
    read_manifest,
    save_arrays,
    save_manifest,
    write_folder,
)

VERSION = MACHINE_VERSION
ENTRY_KEYS = ("name", "split", "file", "sha256")  # set here, not by a caller's details
AGAIN = "write the dataset again with this flexff version"


@dataclass(frozen=True)
class MachineDataset:
    """A loaded machine dataset folder."""

    path: Path
    machine: Mapping[str, Any]  # the description it was written for (`describe`)
    sample_rate_hz: float
    source: str
    trajectories: tuple[Trajectory, ...]
    digest: str  # sha256 of the whole manifest, splits included: what a run trained on
    description: Machine  # the whole description (limits, prior) it was written with

    @property
    def signals(self) -> tuple[str, ...]:
        """Every trajectory's columns: `time`, then the description's signals."""
        return ("time", *description_signals(self.machine))

    def split(self, name: str) -> list[Trajectory]:
        """The trajectories of split `name` ('train' or 'test'), in manifest order."""
        return [t for t in self.trajectories if t.split == name]


def describe(machine: Machine) -> dict[str, Any]:
    """The machine as a dataset's manifest holds it: what its data mean (names, units,
    signals), not how a loop wires or excites it."""
    return {"name": machine.name, "axes": [
        {"name": a.name, "unit": a.unit, "effort_unit": a.effort_unit,
         "signals": {"reference": a.reference, "derivatives": list(a.derivatives),
                     "measured": a.measured_signal, "effort": a.effort_signal}}
        for a in machine.axes]}


def description_signals(description: Mapping[str, Any]) -> tuple[str, ...]:
    """A described machine's dataset signals, in Machine.signals's order."""
    axes = [a["signals"] for a in description["axes"]]
    return (*(n for s in axes for n in (s["reference"], *s["derivatives"])),
            *(s["measured"] for s in axes), *(s["effort"] for s in axes))


def write_machine_dataset(out: str | Path, machine: Machine,
                          trajectories: Mapping[str, Mapping[str, np.ndarray]], rate_hz: float,
                          splits: Mapping[str, str], source: str,
                          details: Mapping[str, Mapping[str, Any]] | None = None
                          ) -> MachineDataset:
    """Write `trajectories` (name -> `time` and machine.signals) sampled at `rate_hz` as the
    new folder `out`, each in its split, with `details[name]` added to its manifest entry
    (`derived`, where it came from); return the folder as loaded."""
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise DatasetError(f"{out} exists and is not an empty folder: write into a new folder")
    details = details or {}
    entries = []
    for name in trajectories:
        extra = dict(details.get(name, {}))
        fixed = sorted(set(extra) & set(ENTRY_KEYS))
        if fixed:
            raise ValueError(f"trajectory {name!r}: details may not set {', '.join(fixed)}")
        entries.append({"name": name, "split": splits.get(name), "file": f"{name}.npz", **extra})

    def fill(folder: Path) -> None:
        for entry in entries:
            save_trajectory(folder / entry["file"], machine, trajectories[entry["name"]])
        write_machine_manifest(folder, machine, rate_hz, entries, source)

    write_folder(out, fill)
    return load_machine_dataset(out, machine)


def save_trajectory(path: Path, machine: Machine, signals: Mapping[str, np.ndarray]) -> None:
    """Write one trajectory's `time` and machine.signals to the .npz `path`, atomically."""
    missing = [s for s in ("time", *machine.signals) if s not in signals]
    if missing:
        raise DatasetError(f"{path.stem}: trajectory lacks signals {', '.join(missing)}")
    save_arrays(path, {s: signals[s] for s in ("time", *machine.signals)})


def write_machine_manifest(folder: Path, machine: Machine, rate_hz: float,
                           entries: list[dict[str, Any]], source: str) -> None:
    """Write the manifest of the trajectory files in `folder` (entries: name, split, file,
    optionally derived and more), adding each file's sha256 and the manifest's own."""
    entries = [{**e, "sha256": file_sha256(folder / e["file"])} for e in entries]
    manifest = {"format": FORMAT, "version": VERSION, "source": source,
                "sample_rate_hz": rate_hz, "machine": describe(machine),
                "description": machine_table(machine), "trajectories": entries}
    manifest["sha256"] = digest(manifest, splits=False)
    _check_manifest(manifest, folder / MANIFEST)
    save_manifest(folder, manifest)


def load_machine_dataset(path: str | Path, machine: Machine | None = None) -> MachineDataset:
    """Read and check a machine dataset folder, and, given `machine`, that it was written for
    that description; raise DatasetError saying what is wrong and what to do."""
    path = Path(path)
    manifest_path, manifest = read_manifest(path, AGAIN)
    _check_manifest(manifest, manifest_path)
    fix = f"write it again ({manifest['source']})"
    if manifest["sha256"] != digest(manifest, splits=False):
        raise DatasetError(f"{manifest_path} was edited: its machine, sample rate or trajectory "
                           f"list no longer match its sha256 (only a trajectory's 'split' may "
                           f"be changed by hand): undo the edit, or {fix}")
    if machine is not None and describe(machine) != manifest["machine"]:
        where = _difference(manifest["machine"], describe(machine), "machine")
        raise DatasetError(f"{manifest_path}: written for another machine description ({where}"
                           f"): use the description it was written for, or {fix} with this one")
    rate_hz = float(manifest["sample_rate_hz"])
    signals = ("time", *description_signals(manifest["machine"]))
    trajectories = tuple(_load_trajectory(path, entry, signals, rate_hz, fix)
                         for entry in manifest["trajectories"])
    return MachineDataset(path, manifest["machine"], rate_hz, manifest["source"], trajectories,
                          digest(manifest, splits=True),
                          parse_machine(manifest["description"], str(manifest_path)))


def is_machine_dataset(path: str | Path) -> bool:
    """Whether the folder's manifest is a machine dataset's (not the manipulator's)."""
    try:
        manifest = json.loads((Path(path) / MANIFEST).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(manifest, dict) and manifest.get("version") == VERSION


def _check_manifest(manifest: Any, where: Path) -> None:
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        found = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        raise DatasetError(f"{where}: format is {found!r}, expected {FORMAT!r}; {AGAIN}")
    version = manifest.get("version")
    if version in MANIPULATOR_VERSIONS:
        raise DatasetError(f"{where}: a dataset of version {version}, the manipulator's signals "
                           f"without a machine description: read it with "
                           f"learning.dataset.load_dataset, or import or collect its data again "
                           f"with a machine description (flexff data import --machine)")
    if version != VERSION:
        raise DatasetError(f"{where}: dataset version {version!r}, this flexff reads machine "
                           f"datasets of version {VERSION}; {AGAIN}")
    if not is_sha256(manifest.get("sha256")) or not isinstance(manifest.get("source"), str):
        raise DatasetError(f"{where}: 'sha256' or 'source' is missing or wrong; {AGAIN}")
    rate_hz = manifest.get("sample_rate_hz")
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, int | float) \
            or not np.isfinite(rate_hz) or rate_hz <= 0:
        raise DatasetError(f"{where}: 'sample_rate_hz' must be a positive number, got {rate_hz!r}")
    if not _is_description(manifest.get("machine")) \
            or not isinstance(manifest.get("description"), dict):
        raise DatasetError(f"{where}: 'machine' is not a machine description (name, axes with "
                           f"their signals); {AGAIN}")
    check_entries(manifest.get("trajectories"), where, AGAIN)
    references = {s for a in manifest["machine"]["axes"]
                  for s in (a["signals"]["reference"], *a["signals"]["derivatives"])}
    for entry in manifest["trajectories"]:
        measured = sorted(set(entry.get("derived", {})) - references)
        if measured:
            raise DatasetError(f"{where}: trajectory {entry['name']!r}: {', '.join(measured)} "
                               f"marked derived, but only references may be: measured positions "
                               f"and efforts must come from the data")


def _is_description(value: Any) -> bool:
    try:
        signals = description_signals(value)
    except (KeyError, TypeError):
        return False
    return bool(signals) and isinstance(value.get("name"), str) and all(
        isinstance(s, str) for s in signals)


def _difference(found: Any, given: Any, key: str) -> str:
    """Where two descriptions first differ, as `key.path: found here, given there`."""
    if isinstance(found, dict) and isinstance(given, dict):
        for name in sorted(set(found) | set(given)):
            if found.get(name) != given.get(name):
                return _difference(found.get(name), given.get(name), f"{key}.{name}")
    if isinstance(found, list) and isinstance(given, list):
        if len(found) != len(given):
            return f"{key}: {len(found)} in the folder, {len(given)} in the description"
        k = next(k for k, (a, b) in enumerate(zip(found, given)) if a != b)
        return _difference(found[k], given[k], f"{key}[{k}]")
    return f"{key} is {found!r} in the folder, {given!r} in the description"


def _load_trajectory(folder: Path, entry: Mapping[str, Any], signals: tuple[str, ...],
                     rate_hz: float, fix: str) -> Trajectory:
    file = folder / entry["file"]
    arrays = read_arrays(folder, entry, signals, fix)
    missing = [s for s in signals if s not in arrays]
    if missing:
        raise DatasetError(f"{file} lacks signals {missing}; {fix}")
    check_arrays(file, arrays, rate_hz, fix)
    return Trajectory(name=entry["name"], split=entry["split"], signals=arrays,
                      reference=entry.get("reference", {}), seed=int(entry.get("seed", 0)),
                      derived=entry.get("derived", {}))
