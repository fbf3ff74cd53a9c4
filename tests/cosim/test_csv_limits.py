"""A CSV table's columns are bounded before its rows are read (fmu.limits.CSV_COLUMNS, one
line naming the limit and how to raise it), and a wide table within the bound is read in time
linear in its columns (the header's checks used to take quadratic time)."""

import time

import pytest

from flexff.cosim.csv_text import read_time_table
from flexff.fmu.errors import InputError


def wide_table(path, columns):
    names = ",".join(f"c{j}" for j in range(columns))
    row = ",".join(["1.5"] * columns)
    path.write_text(f"time,{names}\n0,{row}\n1,{row}\n")
    return path


def test_a_wide_table_is_read_in_linear_time(tmp_path):
    path = wide_table(tmp_path / "wide.csv", 50_000)
    began = time.monotonic()
    table = read_time_table(path)
    assert time.monotonic() - began < 20.0  # quadratic: over two minutes
    assert len(table.columns) == 50_001 and table.columns["c49999"].tolist() == [1.5, 1.5]


def test_too_many_columns_are_refused_before_the_rows(tmp_path, monkeypatch):
    path = wide_table(tmp_path / "wider.csv", 1_000)
    monkeypatch.setenv("FLEXFF_MAX_CSV_COLUMNS", "500")
    with pytest.raises(InputError) as refused:
        read_time_table(path)
    assert str(refused.value) == (f"{path}: the header row: 1,001 columns, more than the limit "
                                  f"of 500; if that is meant, raise it: "
                                  f"FLEXFF_MAX_CSV_COLUMNS=1001 flexff ...")
    monkeypatch.setenv("FLEXFF_MAX_CSV_COLUMNS", "1001")
    assert len(read_time_table(path).columns) == 1_001
