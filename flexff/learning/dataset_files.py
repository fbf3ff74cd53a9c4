"""A dataset folder's files, for any machine: one .npz of signals per trajectory, the sha256s
that guard them, the checks of the manifest's trajectory entries and of the signals as read,
and a folder written whole or not at all.

learning.dataset (the manipulator's folders, versions 2 and 3) and learning.machine_dataset
(any machine's, version 4) build on it, so both formats refuse a damaged folder alike.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.recording import atomic_write
from flexff.fmu.errors import InputError

FORMAT = "flexff-dataset"
MANIPULATOR_VERSIONS = (2, 3)  # learning.dataset's: the manipulator's signals
MACHINE_VERSION = 4  # learning.machine_dataset's: a machine description's signals
MANIFEST = "manifest.json"
SPLITS = ("train", "test")


class DatasetError(InputError):
    """A dataset folder that cannot be used; the message says which file and what to do."""


@dataclass(frozen=True)
class Trajectory:
    """One recorded run: its manifest entry and its signals (float64 arrays of equal length)."""

    name: str
    split: str
    signals: Mapping[str, np.ndarray]
    reference: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    derived: Mapping[str, str] = field(default_factory=dict)  # signal -> how it was computed

    def __len__(self) -> int:
        return len(self.signals["time"])


def digest(manifest: Mapping[str, Any], splits: bool) -> str:
    """sha256 of the manifest but its own hash (and, unless `splits`, the trajectories' splits:
    the one field a user may edit by hand)."""
    content = {k: v for k, v in manifest.items() if k != "sha256"}
    content["trajectories"] = [{k: v for k, v in e.items() if splits or k != "split"}
                               for e in manifest["trajectories"]]
    text = json.dumps(content, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def is_sha256(value: Any) -> bool:
    return isinstance(value, str) and len(value) == 64 and all(c in "0123456789abcdef"
                                                               for c in value)


def save_arrays(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """Write `arrays` as float64 to the .npz `path`, atomically."""
    values = {name: np.asarray(a, dtype=np.float64) for name, a in arrays.items()}

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as handle:  # a file object keeps numpy from adding ".npz"
            # numpy's stub types savez's **kwds and its allow_pickle: bool alike
            np.savez(handle, **values)  # type: ignore[arg-type]

    atomic_write(path, write)


def save_manifest(folder: Path, manifest: Mapping[str, Any]) -> None:
    """Write `manifest` as the folder's MANIFEST (indented JSON), atomically."""
    text = json.dumps(manifest, indent=2) + "\n"
    atomic_write(folder / MANIFEST, lambda tmp: tmp.write_text(text))


def read_manifest(folder: Path, redo: str) -> tuple[Path, Any]:
    """The path of a dataset folder's manifest and its content, unchecked; DatasetError (with
    `redo`, what to do) where it is missing or not JSON."""
    path = folder / MANIFEST
    if not path.is_file():
        raise DatasetError(f"{folder} is not a flexff dataset: {MANIFEST} is missing ({redo})")
    try:
        return path, json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise DatasetError(f"{path} is not valid JSON ({err}); {redo}") from None


def check_entries(entries: Any, where: Path, redo: str) -> None:
    """Refuse trajectory entries without name, split, file and sha256, with a split not in
    SPLITS, a name twice, or a `derived` that is no map of signal to text; `redo` says what to
    do about a folder a flexff wrote otherwise."""
    if not isinstance(entries, list) or not entries:
        raise DatasetError(f"{where}: no trajectories listed; {redo}")
    names = set()
    for k, entry in enumerate(entries):
        if not isinstance(entry, dict) or not {"name", "split", "file", "sha256"} <= set(entry):
            raise DatasetError(f"{where}: trajectory entry {k} needs 'name', 'split', 'file' and "
                               f"'sha256'; {redo}")
        if not isinstance(entry["name"], str) or not isinstance(entry["file"], str):
            raise DatasetError(f"{where}: trajectory entry {k}: 'name' and 'file' must be text")
        if not is_sha256(entry["sha256"]):
            raise DatasetError(f"{where}: trajectory {entry['name']!r} has no valid 'sha256'; "
                               f"{redo}")
        if entry["split"] not in SPLITS:
            raise DatasetError(f"{where}: trajectory {entry['name']!r} has split "
                               f"{entry['split']!r}, expected one of {SPLITS}")
        if entry["name"] in names:
            raise DatasetError(f"{where}: trajectory name {entry['name']!r} appears twice")
        names.add(entry["name"])
        derived = entry.get("derived", {})
        if not isinstance(derived, dict) or not all(isinstance(k, str) and isinstance(v, str)
                                                    for k, v in derived.items()):
            raise DatasetError(f"{where}: trajectory {entry['name']!r}: 'derived' must map "
                               f"signal names to text")


def read_arrays(folder: Path, entry: Mapping[str, Any], names: Iterable[str], fix: str
                ) -> dict[str, np.ndarray]:
    """The arrays `names` that the entry's .npz holds, as float64, after checking the file is
    there, readable and the one whose sha256 the entry lists; `fix` says what to do."""
    file = folder / entry["file"]
    if not file.is_file():
        raise DatasetError(f"{file} is listed in {MANIFEST} but missing; {fix}")
    content = file.read_bytes()
    try:
        with np.load(io.BytesIO(content)) as npz:
            arrays = {n: np.asarray(npz[n], dtype=np.float64) for n in names if n in npz.files}
    except (zipfile.BadZipFile, EOFError, ValueError, OSError):
        raise DatasetError(f"{file} is truncated or not a .npz file; {fix}") from None
    if hashlib.sha256(content).hexdigest() != entry["sha256"]:
        raise DatasetError(f"{file} is not the file {MANIFEST} lists for trajectory "
                           f"{entry['name']!r} (its sha256 differs: changed, or swapped with "
                           f"another trajectory's); {fix}")
    return arrays


def check_arrays(file: Path, signals: Mapping[str, np.ndarray], rate_hz: float, fix: str) -> None:
    """Refuse signals that are not 1-D arrays of equal length, hold NaN or Inf, or whose
    `time` is not sampled at `rate_hz` Hz."""
    lengths = {s: a.shape for s, a in signals.items()}
    if any(a.ndim != 1 for a in signals.values()) or len(set(lengths.values())) != 1:
        raise DatasetError(f"{file}: signals must be 1-D arrays of equal length, got {lengths}; "
                           f"{fix}")
    for s, a in signals.items():
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise DatasetError(f"{file}: signal {s!r} has {bad.size} NaN/Inf value(s), first at "
                               f"sample {bad[0]}; fix or drop this trajectory, or {fix}")
    steps = np.diff(signals["time"])
    if steps.size == 0 or not np.allclose(steps, 1.0 / rate_hz, rtol=1e-6, atol=1e-9):
        raise DatasetError(f"{file}: 'time' must be sampled at the manifest's {rate_hz:g} Hz "
                           f"(steps of {1.0 / rate_hz:g} s); {fix}")


def write_folder(out: Path, fill: Callable[[Path], None]) -> None:
    """The folder `out`, filled by `fill` under a temporary name beside it, then renamed: an
    error leaves `out` as it was."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    try:
        fill(tmp)
        os.chmod(tmp, 0o755)  # mkdtemp's folder is private to its owner
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
