"""Fuzzing CSV time tables (cosim.csv_text.read_time_table, the reader of references, [[source]]
tables and machine logs) and the CSV reference built on it (cosim.references.read_csv): the
repository's own tables mutated, tables of odd cells, and garbage (tests/fuzz/harness.py)."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from pathlib import Path
from unittest import mock

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from flexff.cosim import csv_text
from flexff.cosim.csv_text import TimeTable, read_time_table
from flexff.fmu.errors import InputError
from flexff.plant.paths import read_csv
from tests.fuzz.harness import check, fast, fuzz_seconds, run_for, slow
from tests.fuzz.mutations import ODD_TEXTS, garbage, mutated_bytes
from tests.helpers import REPOSITORY

EXAMPLES = [REPOSITORY / "flexff" / "cosim" / "examples" / "third-party-fmus.csv",
            REPOSITORY / "flexff" / "machines" / "examples" / "drive-reference.csv"]
REFERENCE = b"time,x_ref,y_ref\n" + b"".join(
    f"{k * 0.01:.2f},{0.001 * k:.4f},{-0.0005 * k:.4f}\n".encode() for k in range(40))
VALID = [*(p.read_bytes()[:4000] for p in EXAMPLES), REFERENCE]  # a head: small examples
NAMES = ["time", "t", "x_ref", "y_ref", "vx_ref", "setpoint", "Fx_ff", " time ", "", "time"]
COLUMNS = [(), ("x_ref", "y_ref"), ("setpoint",), ("time",)]
_files = itertools.count()


@st.composite
def tables(draw: st.DrawFn) -> bytes:
    """A table of odd cells: a header of known and odd names, rows of numbers and odd text,
    written with commas, quotes and line ends of every kind."""
    names = draw(st.lists(st.sampled_from(NAMES + ODD_TEXTS[:8]), min_size=1, max_size=5))
    cell = st.one_of(st.floats().map(repr), st.integers().map(str), st.sampled_from(ODD_TEXTS))
    width = st.integers(max(0, len(names) - 1), len(names) + 1)
    rows = draw(st.lists(width.flatmap(lambda n: st.lists(cell, min_size=n, max_size=n)),
                         max_size=12))
    end = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    quote = draw(st.booleans())
    text = end.join(",".join(f'"{c}"' if quote else c for c in row) for row in [names, *rows])
    return draw(st.sampled_from(["", "\ufeff"])).encode() + text.encode()


@st.composite
def plain_tables(draw: st.DrawFn) -> bytes:
    """A table of numbers alone, as flexff and most tools write them: the fast reader's
    case, with the quirks it must hand on (a blank or short row, a NaN, a last line end)."""
    names = draw(st.lists(st.sampled_from(NAMES), min_size=1, max_size=4))
    number = st.floats(allow_nan=draw(st.booleans()), width=64).map(repr)
    rows = draw(st.lists(st.lists(number, min_size=len(names), max_size=len(names)),
                         max_size=8))
    if rows and draw(st.booleans()):  # a blank or a short row
        rows.insert(draw(st.integers(0, len(rows))), draw(st.sampled_from([[], rows[0][:-1]])))
    end = draw(st.sampled_from(["\n", "\r\n"]))
    text = end.join(",".join(row) for row in [names, *rows]) + draw(st.sampled_from(["", end]))
    return text.encode()


contents = st.one_of(st.sampled_from(VALID).flatmap(mutated_bytes), tables(), garbage())


def _file(folder: Path, data: bytes) -> Path:
    """`data` in a new file in `folder` (its name numbered: a failing example's file is
    left behind under its own name)."""
    path = folder / f"table-{next(_files)}.csv"
    path.write_bytes(data)
    return path


def fuzz_tables(folder: Path, data: bytes, required: tuple[str, ...], everything: bool,
                step: float) -> None:
    """The property for one file: as a time table, and as a reference at `step` seconds."""
    path = _file(folder, data)
    check(lambda: read_time_table(path, required, None if everything else ("vx_ref",)))
    check(lambda: read_csv(path, step))
    path.unlink()


examples = dict(data=contents, required=st.sampled_from(COLUMNS), everything=st.booleans(),
                step=st.sampled_from([1e-3, 0.01, 1e-9, 7.0, 5e-324]))


@fast()
@given(**examples)
@example(data=b"\n0,1,2\n1,2,3\n", required=(), everything=False, step=1e-3)  # no header
@example(data=b"time;x_ref\n0;1\n1;2\n", required=(), everything=False, step=1e-3)
def test_csv_fast(tmp_path: Path, data: bytes, required: tuple[str, ...], everything: bool,
                  step: float) -> None:
    fuzz_tables(tmp_path, data, required, everything, step)


def _outcome(read: Callable[[], TimeTable]) -> object:
    """A table's columns and lines, or the error's message."""
    try:
        table = read()
    except InputError as error:
        return str(error)
    return {name: values.tolist() for name, values in table.columns.items()}, table.lines


@fast()
@given(data=st.one_of(st.sampled_from(VALID), plain_tables(), tables(), contents),
       required=st.sampled_from(COLUMNS), everything=st.booleans())
def test_the_plain_tables_reader_reads_as_the_careful_one(
        tmp_path: Path, data: bytes, required: tuple[str, ...], everything: bool) -> None:
    """numpy's parser, taken for plain files (csv_text._plain_table), gives what the careful
    reader gives: the same columns, lines and errors."""
    path = _file(tmp_path, data)

    def read() -> TimeTable:
        return read_time_table(path, required, None if everything else ("vx_ref",))

    fast_outcome = _outcome(read)
    with mock.patch.object(csv_text, "_plain_table", lambda path: None):
        assert fast_outcome == _outcome(read)
    path.unlink()


@pytest.mark.slow
def test_csv_slow(tmp_path: Path) -> None:
    @slow()
    @given(**examples)
    def fuzz_round(data: bytes, required: tuple[str, ...], everything: bool,
                   step: float) -> None:
        fuzz_tables(tmp_path, data, required, everything, step)

    run_for(fuzz_seconds(), fuzz_round)


def test_smoothing_window_bounded(tmp_path: Path) -> None:
    """Found by the fuzzer: a 10^-9 s step made the smoothing window 25 * 10^6 samples, and
    scipy's filter crashed the process (a segmentation fault); now one line names the limit."""
    path = _file(tmp_path, REFERENCE)
    with pytest.raises(InputError, match=r"smoothing window .* FLEXFF_MAX_SMOOTHING_SAMPLES"):
        read_csv(path, 1e-9)
    # and a step of 5e-324 s made it infinite (an OverflowError)
    with pytest.raises(InputError, match="smoothing window"):
        read_csv(path, 5e-324)
