"""`flexff data import`: logs of a real machine (CSV or MATLAB .mat) as a dataset folder.

Each file is one trajectory, named by its file name without suffix. Columns (CSV: a header row
naming them; .mat: variables of those names, vectors): `time` [s], `theta_s1..3` [rad, the
shoulder angles as flexff's plant gives them: the wrist at the centre at the home angles],
`Fx`, `Fy` [N] (the force applied to the wrist) are required; the reference `x_ref .. ay_ref`
is optional; other columns are ignored. MATLAB v4/v5/v7 files are read by scipy, v7.3 files
(HDF5) by h5py where it is installed.

Everything is checked before anything is written, and an error names the file, the column and
the row (`data row N`: 1-based, the CSV header not counted; a CSV error names its line too): a
missing column, NaN or Inf, time not strictly increasing, a sample interval more than 1 % off
the file's median, fewer samples than one training window (learning.presets), encoder angles
that no wrist position fits.

Time is counted from each log's first sample (its own first time is kept in the manifest).
The dataset's rate is `rate` or the logs' own (which must agree to 1 %; rounded to a whole
number of Hz where that changes it by at most 0.1 %). A log already sampled
at that rate (to the dataset loader's 1e-6) is kept bit for bit; one at a whole multiple keeps
every n-th sample (plain decimation, as data collection); any other is interpolated linearly
onto a uniform grid from its first time.

What the format needs and the logs do not hold is derived, and marked so in the trajectory's
manifest entry (`derived`): the true position x, y from the encoders by the nominal forward
kinematics (three encoders, least squares), and a missing reference signal: a position from
the derived position, a velocity or acceleration by a cubic Savitzky-Golay filter over
log_files.SMOOTHING_S of the reference position, as cosim.references.read_csv derives them. Training
reads only the encoders and the forces (learning.dataset.TRAINED), never a derived signal.

The folder is written under a temporary name beside `out` and renamed at the end, so an error
leaves `out` as it was.
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
    rate = rate_hz or common_rate(logs)
    trajectories = [(log, *resampled(log, rate)) for log in logs]
    for log, signals, _ in trajectories:
        check_length(log, len(signals["time"]), rate)
    entries: list[dict[str, Any]] = []
    written = []
    for log, signals, how in trajectories:
        derived = _derive(log, signals, rate)
        written.append(signals)
        entries.append({"name": log.path.stem, "split": splits[log.path.stem],
                        "file": f"{log.path.stem}.npz", "reference": {}, "seed": 0,
                        "derived": derived, "log": log_entry(log, how)})

    def fill(folder: Path) -> None:
        for entry, values in zip(entries, written):
            save_signals(folder / entry["file"], values)
        write_manifest(folder, SET, rate, {"kind": "measured logs"}, entries, IMPORTED)

    write_folder(out, fill)
    return load_dataset(out)


def _derive(log: Log, signals: dict[str, np.ndarray], rate: float) -> dict[str, str]:
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
                    signals[ref], rate, order, f"{'the derived ' if ref in derived else ''}{ref}")
    return derived
