"""Recorded signals of a run and their files.

`signals.parquet` holds `time` [s] and one float64 column per recorded signal, exactly as the
run had them. A run writes its record while it runs, one complete Parquet file per chunk in
`signals.parts/` (RecordWriter), joined into signals.parquet at the end; a killed run keeps
its chunks, which load_recording reads. `signals.csv` is written on request only. Records of
earlier versions, `signals.npz`, still load.

The files: "File formats" (docs/reference/file-formats.md); why Parquet and why chunks: "A
run's cost and real time" (docs/explanation/run-cost.md).
"""

from __future__ import annotations

import csv as csv_module
import os
import shutil
import tempfile
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from flexff.fmu.errors import InputError

PARQUET_NAME = "signals.parquet"
PARTS_NAME = "signals.parts"  # the chunks of a run that is running or was killed
CSV_NAME = "signals.csv"
NPZ_NAME = "signals.npz"  # the record of earlier versions (read only)
CHUNK_BYTES = 4 * 2**20  # a chunk's values (at least CHUNK_MIN_ROWS points)
JOIN_ROWS = 2**16  # points per row group of a joined record
CHUNK_MIN_ROWS = 1000  # a chunk's points are a multiple of it (the master's progress step)
# plain encoding, uncompressed: float signals barely compress, and a dictionary per column
# costs time and memory that grows with the number of chunks
PARQUET_OPTIONS: dict[str, Any] = {"compression": "none", "use_dictionary": False}


class RecordError(OSError):
    """A record's file that could not be written (a full disk), named by its path."""

    @classmethod
    def of(cls, error: OSError, path: Path) -> RecordError:
        """`error` (whose own text may name no file, as pyarrow's does not) about `path`."""
        reason = os.strerror(error.errno) if error.errno else (error.strerror or str(error))
        return cls(error.errno, reason, str(path))


@dataclass(frozen=True, eq=False)
class Recording:
    """Signals sampled at the communication points `time` (one value per point each)."""

    time: np.ndarray
    signals: Mapping[str, np.ndarray]
    wall_s: float = 0.0  # seconds the stepping loop took (0 for a reloaded recording)
    timing: Any = None  # cosim.timing.StepTiming of the run (None for a reloaded recording)

    def __post_init__(self) -> None:
        if "time" in self.signals:
            raise InputError("'time' is reserved for the time axis and cannot be a signal name")
        for name, values in self.signals.items():
            if values.shape != self.time.shape:
                raise ValueError(f"signal {name!r} has {values.shape} samples, time has "
                                 f"{self.time.shape}")

    def __getitem__(self, name: str) -> np.ndarray:
        """A signal by its name, or by an output's own name where one FMU alone has it
        (`x` for `plant.x`)."""
        if name == "time":
            return self.time
        return self.signals[signal_name(self.signals, name)]

    def __contains__(self, name: str) -> bool:
        try:
            self[name]
        except KeyError:
            return False
        return True

    @property
    def step(self) -> float:
        """Communication step [s] (the spacing of `time`)."""
        return float(self.time[1] - self.time[0]) if self.time.size > 1 else 0.0


def atomic_write(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Call `write(tmp)` on a temporary file next to `path`, then rename it to `path` (what
    `write` returns is ignored)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, 0o644)  # mkstemp creates the file private to its owner
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def signal_name(names: Collection[str], name: str) -> str:
    """The one of `names` that is `name`, or that is `fmu.name` for a single FMU (KeyError)."""
    if name in names:
        return name
    matches = [n for n in names if n.partition(".")[2] == name]
    if len(matches) != 1:
        raise KeyError(name if not matches else f"{name!r} is ambiguous: {matches}")
    return matches[0]


class RecordWriter:
    """Writes a record into `folder` chunk by chunk (the module's doc: signals.parts/, joined
    into signals.parquet by `close`)."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.parts = self.folder / PARTS_NAME
        shutil.rmtree(self.parts, ignore_errors=True)  # a killed earlier run's chunks
        (self.folder / PARQUET_NAME).unlink(missing_ok=True)
        self.parts.mkdir(parents=True)
        self.count = 0  # chunks written
        self.points = 0  # points written
        self.times: tuple[float, float] | None = None  # of the first and the last point

    def write(self, time: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Append the points `time` with their values, one array per signal (RecordError where
        the chunk cannot be written: the chunks before stay as they are)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table({"time": time, **columns})
        path = self._part(self.count)
        try:
            atomic_write(path, lambda tmp: pq.write_table(table, tmp, **PARQUET_OPTIONS))
        except OSError as error:
            raise RecordError.of(error, path) from None
        self.count += 1
        if time.size:
            first = self.times[0] if self.times else float(time[0])
            self.times = (first, float(time[-1]))
            self.points += time.size

    def _part(self, k: int) -> Path:
        return self.parts / f"part-{k:06d}.parquet"

    def held(self) -> dict[str, Any]:
        """What the record holds, for run.json: its points and the times of its first and
        last (None in an empty record)."""
        first, last = self.times or (None, None)
        return {"points": self.points, "first_time": first, "last_time": last}

    def close(self, csv: bool = False) -> list[Path]:
        """Join the chunks this writer wrote (never another's) into signals.parquet (and write
        signals.csv if `csv`); return the files written. RecordError where a file cannot be
        written: the chunks stay until they are joined."""
        import pyarrow.parquet as pq

        parts = [self._part(k) for k in range(self.count)]
        if len(parts) == 1:  # complete as it is
            os.replace(parts[0], self.folder / PARQUET_NAME)
            parts = []

        def join(tmp: Path) -> None:
            schema = pq.read_schema(parts[0])
            with pq.ParquetWriter(tmp, schema, **PARQUET_OPTIONS) as writer:
                for part in parts:  # in slices, so that joining takes little memory
                    for batch in pq.ParquetFile(part).iter_batches(JOIN_ROWS, use_threads=False):
                        writer.write_batch(batch, row_group_size=JOIN_ROWS)

        joined = self.folder / PARQUET_NAME
        try:
            paths = [atomic_write(joined, join) if parts else joined]
        except OSError as error:
            raise RecordError.of(error, joined) from None
        shutil.rmtree(self.parts)
        if csv:
            try:
                paths.append(export_csv(self.folder))
            except OSError as error:
                raise RecordError.of(error, self.folder / CSV_NAME) from None
        return paths


def chunk_rows(columns: int) -> int:
    """Points per chunk of a record of `columns` columns (time included): CHUNK_BYTES of
    values (a multiple of CHUNK_MIN_ROWS), so that a chunk's memory does not depend on how many
    signals a run records."""
    return max(1, CHUNK_BYTES // (8 * max(columns, 1)) // CHUNK_MIN_ROWS) * CHUNK_MIN_ROWS


def save_recording(recording: Recording, folder: str | Path, csv: bool = False) -> list[Path]:
    """Write signals.parquet (and signals.csv if `csv`) into `folder`; return the paths."""
    writer = RecordWriter(folder)
    rows = chunk_rows(1 + len(recording.signals))
    for k in range(0, max(recording.time.size, 1), rows):
        writer.write(recording.time[k:k + rows],
                     {n: v[k:k + rows] for n, v in recording.signals.items()})
    return writer.close(csv)


def _record_files(folder: Path) -> list[Path]:
    """The Parquet files of the record in `folder`: signals.parquet, else a killed run's
    chunks in order."""
    if (folder / PARQUET_NAME).is_file():
        return [folder / PARQUET_NAME]
    return sorted((folder / PARTS_NAME).glob("part-*.parquet"))


def export_csv(folder: str | Path) -> Path:
    """Write signals.csv beside the record in `folder` (module doc), one row group at a time
    (memory flat in the record's length); return its path."""
    import pyarrow.parquet as pq

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder (give the -o folder of flexff run)")
    files = _record_files(folder)
    if not files:
        raise InputError(f"{folder}: no {PARQUET_NAME} (nor {PARTS_NAME}/): not a flexff run "
                         f"folder, or one of an earlier version (flexff.results.load reads it)")

    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="") as handle:
            header = True
            for path in files:
                parquet = pq.ParquetFile(path)
                for group in range(parquet.num_row_groups):
                    arrays = _numpy_columns(parquet.read_row_group(group))
                    if header:
                        handle.write(",".join(arrays) + "\n")
                        header = False
                    _write_rows(handle, arrays)

    return atomic_write(folder / CSV_NAME, write)


def _write_rows(handle: TextIO, arrays: Mapping[str, np.ndarray]) -> None:
    if all(a.dtype == np.float64 for a in arrays.values()):
        np.savetxt(handle, np.column_stack(list(arrays.values())), fmt="%.17g", delimiter=",")
        return
    columns = [[f"{v:.17g}" if a.dtype.kind == "f" else str(v) for v in a]
               for a in arrays.values()]
    csv_module.writer(handle).writerows(zip(*columns))


def _numpy_columns(table: Any) -> dict[str, np.ndarray]:
    """A pyarrow Table's columns as numpy arrays (strings as numpy's str type)."""
    import pyarrow as pa

    return {name: (np.array(column.to_pylist(), dtype=str) if pa.types.is_string(column.type)
                   else column.to_numpy())
            for name, column in zip(table.column_names, table.columns)}


def load_recording(path: str | Path) -> Recording:
    """Read a run's record: a folder (its signals.parquet, a killed run's signals.parts/, or
    an earlier version's signals.npz), or one such file."""
    path = Path(path)
    if path.is_dir() and path.name != PARTS_NAME:
        files = _record_files(path)
        if not files:
            return _load_npz(path / NPZ_NAME)
    elif path.suffix == ".npz":
        return _load_npz(path)
    else:
        files = sorted(path.glob("part-*.parquet")) if path.is_dir() else [path]
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        arrays = _numpy_columns(pa.concat_tables([pq.read_table(f) for f in files]))
    except (pa.ArrowInvalid, OSError) as error:
        raise InputError(f"{path}: not a readable record: {error}") from None
    return _recording(path, arrays)


def _load_npz(path: Path) -> Recording:
    if not path.is_file():
        raise InputError(f"{path.parent}: no record ({PARQUET_NAME}, {PARTS_NAME}/ or "
                         f"{NPZ_NAME}) in this folder")
    with np.load(path) as data:
        return _recording(path, {name: data[name] for name in data.files})


def _recording(path: Path, arrays: dict[str, np.ndarray]) -> Recording:
    if "time" not in arrays:
        raise InputError(f"{path}: no 'time' array, not a flexff recording")
    time = arrays.pop("time")
    return Recording(time, arrays)
