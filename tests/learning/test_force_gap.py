"""learning.force_gap: what a feedforward's force misses against the ILC limit's, by band and
by time shift, and its table in the evaluation report."""

import numpy as np
import pytest

from flexff.cosim.recording import Recording
from flexff.learning.force_gap import band_names, force_gap
from flexff.learning.report import force_gap_table, force_gaps

STEP = 1e-3
T = np.arange(20000) * STEP


def _force(t):
    return 0.2 * np.sin(2 * np.pi * 0.2 * t)


def test_a_delayed_force_is_found_by_its_shift():
    late = _force(T - 0.005)  # the feedforward 5 ms behind the ideal force
    gap = force_gap(late, _force(T), STEP)
    assert gap["best_shift_s"] == pytest.approx(0.005)
    assert gap["rms_at_best_shift_n"] < 1e-9 < gap["rms_n"]
    assert gap["band_share"][band_names()[0]] > 0.99


def test_a_fast_difference_lies_above_the_crossover_and_no_shift_helps():
    ideal = _force(T) + 1e-3 * np.sin(2 * np.pi * 20.0 * T)
    gap = force_gap(_force(T), ideal, STEP)
    assert gap["band_share"][band_names()[-1]] > 0.99
    assert gap["best_shift_s"] == 0.0
    assert gap["rms_n"] == pytest.approx(1e-3 / np.sqrt(2), rel=1e-3)


def test_series_of_other_lengths_are_refused():
    with pytest.raises(ValueError, match="same length"):
        force_gap(np.zeros(10), np.zeros(11), STEP)


def test_the_report_compares_each_feedforward_with_the_limit():
    def recording(fx, fy):
        zero = np.zeros_like(T)
        return Recording(T, {"x_ref": zero, "y_ref": zero, "x": zero, "y": zero,
                             "Fx_fb": zero, "Fy_fb": zero, "Fx_ff": fx, "Fy_ff": fy})

    limit = recording(_force(T), _force(T + 1.0))
    gaps = force_gaps({"pid": recording(0 * T, 0 * T), "identified":
                       recording(_force(T - 0.003), _force(T + 1.0)), "limit": limit})
    assert list(gaps) == ["identified"]
    assert gaps["identified"]["x"]["best_shift_s"] == pytest.approx(0.003)
    assert gaps["identified"]["y"]["rms_n"] == 0.0
    row = next(line for line in force_gap_table(gaps).splitlines()
               if line.startswith("| identified rigid-body FF | x |"))
    assert row.split("|")[-3].strip() == "+3"
    assert not force_gaps({"pid": limit, "identified": limit})  # no limit, no comparison
