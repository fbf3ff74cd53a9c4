"""CSV text files read the one careful way: UTF-8 (a byte-order mark allowed), each row with its
line number, and a file that is no CSV text an error naming the problem, never its content;
and the one reader of time tables on top (references, [[source]] tables, machine logs)."""

from __future__ import annotations

import csv
import io
import itertools
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexff.fmu.errors import InputError
from flexff.fmu.limits import CSV_COLUMNS


def read_rows(path: Path, error: type[InputError] = InputError) -> list[tuple[int, list[str]]]:
    """(line number, cells) of every row of the CSV file at `path`; `error` (an InputError
    type) for a file that is not UTF-8 CSV text or is empty, or whose header row has more
    columns than fmu.limits.CSV_COLUMNS (checked before the rows are read)."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            reader = csv.reader(handle)
            rows = [(reader.line_num, row) for row in itertools.islice(reader, 1)]
            if rows:
                try:
                    CSV_COLUMNS.check(len(rows[0][1]), f"{path}: the header row")
                except InputError as problem:
                    raise error(str(problem)) from None
            rows += [(reader.line_num, row) for row in reader]
    except UnicodeDecodeError as problem:
        raise error(f"{path}: not a CSV text file (no UTF-8 text at byte {problem.start})") \
            from None
    except csv.Error as problem:
        raise error(f"{path}: not a CSV table ({problem})") from None
    if not rows:
        raise error(f"{path}: empty file")
    return rows


@dataclass(frozen=True)
class TimeTable:
    """A CSV table of samples as read: its columns by name (`time` first) and the file line of
    each data row, for messages."""

    path: Path
    columns: dict[str, np.ndarray]
    lines: tuple[int, ...]

    @property
    def time(self) -> np.ndarray:
        return self.columns[TIME]

    def row(self, k: int) -> str:
        """Data row k (from 0) as messages name it."""
        return f"data row {k + 1} (line {self.lines[k]})"


TIME = "time"  # the time column; files written before flexff named it so may call it `t`
OLD_TIME = "t"


def read_time_table(path: Path, required: Sequence[str] = (),
                    optional: Sequence[str] | None = None,
                    error: type[InputError] = InputError, time: str = TIME) -> TimeTable:
    """The time table in the CSV file at `path`: a header row naming `time` (or `t`) and the
    `required` columns, then rows of numbers, every one finite, time strictly increasing. It
    keeps the `required` and `optional` columns (every column when `optional` is None). Every
    problem is an `error` naming the file, column and row (never the file's content): the one
    reader of references, [[source]] tables and machine logs. A machine log's map may name
    the time column otherwise (`time`): the table keeps it as `time`, and does not read a
    column the file names `time`."""
    plain = _plain_table(path)
    rows = read_rows(path, error) if plain is None else [(1, plain[0])]
    header = [name.strip() for name in rows[0][1]]
    if time == TIME and TIME not in header and OLD_TIME in header:
        header[header.index(OLD_TIME)] = TIME
    wanted = [time, *(n for n in required if n != time)]
    missing = [n for n in wanted if n not in header]
    if missing:
        also = f" (optionally {', '.join(optional)})" if optional else ""
        raise error(f"{path}: missing column(s) {', '.join(missing)}: the header row must name "
                    f"{', '.join(wanted)}{also}{_separator_hint(header)}")
    keep = set(wanted) | ({n for n in header if n != TIME} if optional is None
                          else set(optional) - {TIME})
    kept = [n for n in header if n in keep]
    counts = Counter(kept)  # in one pass: a table of 10^6 columns is read in seconds
    for name in kept:
        if counts[name] > 1:
            raise error(f"{path}: column {name} appears {counts[name]} times in the header row")
    column = {name: j for j, name in enumerate(header) if name in keep}
    if plain is not None:
        values = plain[1]
        table = TimeTable(path, {}, tuple(range(2, len(values) + 2)))
        table.columns.update((TIME if name == time else name, values[:, column[name]].copy())
                             for name in kept)
    else:
        body = [(line, row) for line, row in rows[1:] if "".join(row).strip()]
        table = TimeTable(path, {}, tuple(line for line, _ in body))
        for k, (_, cells) in enumerate(body):
            if len(cells) != len(header):
                raise error(f"{path}: {table.row(k)} has {len(cells)} cells, the header "
                            f"{len(header)}")
        for name in kept:
            table.columns[TIME if name == time else name] = _numbers(
                table, name, [cells[column[name]] for _, cells in body], error)
    if len(table.lines) < 2:
        raise error(f"{path}: {len(table.lines)} data row(s): a time table needs at least two")
    steps = np.diff(table.time)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        raise error(f"{path}: column {time}, {table.row(k)}: time does not increase "
                    f"(t = {table.time[k - 1]:.9g} s, then {table.time[k]:.9g} s)")
    return table


def _separator_hint(header: list[str]) -> str:
    """What to do where the header row is one cell holding another separator: a table saved
    with semicolons or tabs (as spreadsheets in many locales save CSV) reads as one column."""
    for separator, name in ((";", "semicolons"), ("\t", "tabs")):
        if len(header) == 1 and separator in header[0]:
            return (f"; the header row is one column that holds {name}: save the table with "
                    f"commas between the columns and points as decimal marks")
    return ""


def _plain_table(path: Path) -> tuple[list[str], np.ndarray] | None:
    """The header cells and the data rows (n, columns) of the CSV file at `path`, the rows
    parsed at once by numpy, where the file is plain: UTF-8, no quotes below the header, no
    blank rows, every row as wide as the header and every cell a finite number. None
    otherwise: the careful reader then reads it and names what is wrong. (A force table of
    1e5 rows: 0.15 s instead of 0.64 s.)"""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError):
        return None
    first, _, body = text.partition("\n")
    header = next(csv.reader([first]), [])
    if '"' in body or not body.strip() or not header or len(header) > CSV_COLUMNS.value():
        return None
    rows = body.count("\n") + (not body.endswith("\n"))
    try:
        values = np.loadtxt(io.StringIO(body), delimiter=",", comments=None, ndmin=2)
    except ValueError:
        return None
    if values.shape != (rows, len(header)) or not np.isfinite(values).all():
        return None
    return header, values


def _numbers(table: TimeTable, name: str, cells: list[str], error: type[InputError]
             ) -> np.ndarray:
    """A column's cells as finite float64 numbers (numpy parses them at once; a cell it
    refuses is then found one by one, for the message)."""
    try:
        values = np.array(cells, dtype=float)
    except ValueError:
        for k, cell in enumerate(cells):
            try:
                float(cell)
            except ValueError:
                raise error(f"{table.path}: column {name}, {table.row(k)}: not a number") \
                    from None
        raise  # numpy refused what Python reads: not expected, so not hidden
    if not np.all(np.isfinite(values)):
        k = int(np.argmin(np.isfinite(values)))
        raise error(f"{table.path}: column {name}, {table.row(k)}: NaN or Inf")
    return values
