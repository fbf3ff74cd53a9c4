"""CSV text files read the one careful way: UTF-8 (a byte-order mark allowed), each row with its
line number, and a file that is no CSV text an error naming the problem, never its content."""

from __future__ import annotations

import csv
from pathlib import Path

from flexff.fmu.errors import InputError


def read_rows(path: Path, error: type[InputError] = InputError) -> list[tuple[int, list[str]]]:
    """(line number, cells) of every row of the CSV file at `path`; `error` (an InputError
    type) for a file that is not UTF-8 CSV text or is empty."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            reader = csv.reader(handle)
            rows = [(reader.line_num, row) for row in reader]
    except UnicodeDecodeError as problem:
        raise error(f"{path}: not a CSV text file (no UTF-8 text at byte {problem.start})") \
            from None
    except csv.Error as problem:
        raise error(f"{path}: not a CSV table ({problem})") from None
    if not rows:
        raise error(f"{path}: empty file")
    return rows
