"""`flexff data import`: logs of a real machine (CSV or MATLAB .mat) as a dataset folder.

Each file is one trajectory. Everything is checked before anything is written, and an error
names the file, the column and the row. Logs are resampled to the dataset's rate (kept, plain
decimation, or linear interpolation). What the format needs and the logs lack (the true
position, a missing reference signal) is derived and marked `derived`; training never reads a
derived signal. The folder is written under a temporary name and renamed at the end.

Docs: "Import a machine's logs" (docs/how-to/import-logs.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexff.learning.dataset import (
    ENCODER_SIGNALS,
    IMPORTED,
    POSITION_SIGNALS,
    REFERENCE_SIGNALS,
    TRAINED,
    Dataset,
    load_dataset,
    save_signals,
    write_manifest,
)
from flexff.learning.dataset_files import write_folder
from flexff.learning.features import encoder_positions
from flexff.learning.log_files import (
    Log,
    LogError,
    check_length,
    check_log,
    check_output,
    common_rate,
    log_entry,
    read_log,
    reference_derivative,
    resampled,
    split_by_file,
)

REQUIRED = TRAINED  # a log must hold what training reads
SET = "hardware"  # logs of a real machine
FK = "forward kinematics of theta_s1..3 (nominal model, least squares)"


def import_logs(files: Sequence[str | Path], out: str | Path, rate_hz: float | None = None,
                test: Sequence[str] | None = None) -> Dataset:
    """Import the log `files` into the new dataset folder `out` at `rate_hz` (default: the
    logs' own), the logs named in `test` (default: the last one) forming the test split;
    return the dataset. Raises LogError (an InputError) naming file, column and row."""
    out = Path(out)
    check_output(out, rate_hz)
    paths = [Path(f) for f in files]
    splits = split_by_file(paths, test)
    logs = [check_log(read_log(p, REQUIRED, REFERENCE_SIGNALS)) for p in paths]
    rate_hz = rate_hz or common_rate(logs)
    trajectories = [(log, *resampled(log, rate_hz)) for log in logs]
    for log, signals, _ in trajectories:
        check_length(log, len(signals["time"]), rate_hz)
    entries: list[dict[str, Any]] = []
    written = []
    for log, signals, how in trajectories:
        derived = _derive(log, signals, rate_hz)
        written.append(signals)
        entries.append({"name": log.path.stem, "split": splits[log.path.stem],
                        "file": f"{log.path.stem}.npz", "reference": {}, "seed": 0,
                        "derived": derived, "log": log_entry(log, how)})

    def fill(folder: Path) -> None:
        for entry, values in zip(entries, written):
            save_signals(folder / entry["file"], values)
        write_manifest(folder, SET, rate_hz, {"kind": "measured logs"}, entries, IMPORTED)

    write_folder(out, fill)
    return load_dataset(out)


def _derive(log: Log, signals: dict[str, np.ndarray], rate_hz: float) -> dict[str, str]:
    """Add the signals the log lacks to `signals`; return how each was derived."""
    theta = np.column_stack([signals[n] for n in ENCODER_SIGNALS])
    position = encoder_positions(theta, 3)
    bad = np.flatnonzero(~np.all(np.isfinite(position), axis=1))
    if bad.size:
        raise LogError(f"{log.path}: columns theta_s1..3, data row {bad[0] + 1} (after "
                       f"resampling): no wrist position fits these angles (are they the shoulder "
                       f"angles in rad, as flexff's plant gives them?)")
    derived = {}
    for axis, column in zip(POSITION_SIGNALS, position.T):
        signals[axis] = np.ascontiguousarray(column)
        derived[axis] = FK
    for axis in POSITION_SIGNALS:
        ref = f"{axis}_ref"
        if ref not in signals:
            signals[ref] = signals[axis]
            derived[ref] = f"the derived position {axis} (the log has no {ref})"
        for order, prefix in ((1, "v"), (2, "a")):
            name = f"{prefix}{axis}_ref"
            if name not in signals:
                signals[name], derived[name] = reference_derivative(
                    signals[ref], rate_hz, order,
                    f"{'the derived ' if ref in derived else ''}{ref}")
    return derived
