"""Reference trajectories against independent checks: finite differences, the thesis's eqs. (4.1)
and (4.2) written out, the thesis's evaluation landmarks, workspace and argument errors, CSV."""

import math

import numpy as np
import pytest

from flexff.cosim.memory import MemoryNeeded, available_memory
from flexff.plant.paths import (
    Chain,
    Circle,
    Hold,
    Line,
    Reference,
    Spline,
    read_csv,
    sample,
)
from flexff.plant.references import thesis_evaluation, thesis_evaluation_path

STEP = 1e-3


def some_paths():
    """One path of every kind, and a chain of line, hold, circle, hold."""
    line = Line((0.0, 0.0), (0.02, 0.01), 2.0)
    circle = Circle((0.0, 0.0), math.hypot(0.02, 0.01), math.atan2(0.01, 0.02), -2.5, 5.0)
    chain = Chain((line, Hold(line.end_point, 0.5), circle, Hold(tuple(circle.end), 0.7)))
    spline = Spline(((0, 0), (-0.006, -0.0321), (-0.02, -0.007), (-0.03, -0.035)), 6.0)
    return {"line": line, "circle": circle, "chain": chain, "spline": spline,
            "thesis": thesis_evaluation_path()}


@pytest.mark.parametrize("name", ["line", "circle", "chain", "spline", "thesis"])
def test_velocity_and_acceleration_match_finite_differences(name):
    ref = sample(some_paths()[name], STEP)
    for pos, vel, acc in ((ref.x, ref.vx, ref.ax), (ref.y, ref.vy, ref.ay)):
        scale_v, scale_a = np.abs(vel).max() + 1e-12, np.abs(acc).max() + 1e-12
        fd_v = np.gradient(pos, STEP, edge_order=2)
        fd_a = np.gradient(vel, STEP, edge_order=2)
        assert np.abs(fd_v - vel).max() < 1e-4 * scale_v
        assert np.abs(fd_a - acc).max() < 1e-3 * scale_a  # a spline's jerk jumps at knots


def test_circle_and_line_follow_the_seed_equations():
    t = np.linspace(0, 4.0, 401)
    radius, theta0, turns, tm = 0.03, 0.75 * math.pi, 3.0, 4.0
    theta_ref = 2 * math.pi * t / tm - 2 * math.pi * np.sin(2 * math.pi * t / tm) / (2 * math.pi)
    for sign in (1, -1):
        circle = Circle((0, 0), radius, theta0, sign * turns, tm).evaluate(t)
        angle = theta0 + sign * turns * theta_ref
        assert np.allclose(circle[0], radius * np.cos(angle), atol=1e-15)
        assert np.allclose(circle[1], radius * np.sin(angle), atol=1e-15)
    hx, hy = 0.035, -0.02
    line = Line((0, 0), (hx, hy), tm).evaluate(t)
    assert np.allclose(line[0], hx * t / tm - hx * np.sin(2 * math.pi * t / tm) / (2 * math.pi))
    assert np.allclose(line[1], hy * t / tm - hy * np.sin(2 * math.pi * t / tm) / (2 * math.pi))


def test_direction_of_the_circle():
    """Positive turns run counter-clockwise: the angular momentum x vy - y vx is positive."""
    t = np.linspace(0.1, 0.9, 9)
    for turns in (1.0, -1.0):
        s = Circle((0, 0), 0.02, 0.0, turns, 1.0).evaluate(t)
        assert np.all(np.sign(s[0] * s[3] - s[1] * s[2]) == np.sign(turns))


def test_thesis_evaluation_landmarks():
    ref = thesis_evaluation(STEP)
    assert ref.t[0] == 0 and ref.t[-1] == pytest.approx(15.0) and ref.duration == pytest.approx(15)
    assert len(ref.t) == 15001
    k3 = round(3.0 / STEP)
    assert (ref.x[k3], ref.y[k3]) == (pytest.approx(0.0098, abs=1e-15),
                                      pytest.approx(-0.0098, abs=1e-15))
    assert (ref.x[0], ref.y[0]) == (0, 0)
    for k in (0, k3, -1):  # at rest at the start, the junction and the end
        assert abs(ref.vx[k]) + abs(ref.vy[k]) < 1e-12
    # straight line before 3 s: along the -45 degree diagonal
    assert np.allclose(ref.x[:k3], -ref.y[:k3], atol=1e-15)
    # circle after 3 s: radius 0.014 about a centre within 0.15 mm of the workspace centre
    circle = thesis_evaluation_path().segments[1]
    assert np.hypot(*circle.centre) < 1.5e-4
    dx, dy = ref.x[k3:] - circle.centre[0], ref.y[k3:] - circle.centre[1]
    assert np.allclose(np.hypot(dx, dy), 0.014, atol=1e-15)
    swept = np.unwrap(np.arctan2(dy, dx))
    assert (swept[-1] - swept[0]) / (2 * math.pi) == pytest.approx(11.5, abs=1e-12)
    assert np.all(np.diff(swept) >= 0)  # one way round, counter-clockwise
    # the mean turning rate of the thesis: 0.958 Hz, over the circle's 12 s
    turns_per_second = (swept[-1] - swept[0]) / (2 * math.pi) / (ref.t[-1] - ref.t[k3])
    assert turns_per_second == pytest.approx(0.958, abs=1e-3)


def test_signals_use_the_cosimulation_names():
    ref = sample(Hold((0.01, 0.0), 0.01), STEP)
    assert list(ref.signals()) == ["x_ref", "y_ref", "vx_ref", "vy_ref", "ax_ref", "ay_ref"]
    assert np.all(ref.signals()["x_ref"] == 0.01) and len(ref.t) == 11


@pytest.mark.parametrize("make, point", [
    (lambda: Line((0, 0), (0.06, 0), 1.0), "(0.06, 0)"),
    (lambda: Circle((0.04, 0.0), 0.02, math.pi, 1.0, 2.0), "(0.06, "),
    (lambda: Hold((0.0, 0.051), 1.0), "(0, 0.051)"),
    (lambda: Spline(((0, 0), (0.049, 0.0), (0.0, 0.049)), 1.0), "lies outside"),
])
def test_leaving_the_workspace_raises_naming_the_point(make, point):
    with pytest.raises(ValueError, match="outside the workspace") as error:
        make()
    assert point in str(error.value)


@pytest.mark.parametrize("make, message", [
    (lambda: Line((0, 0), (0.01, 0), 0.0), "duration must be a positive"),
    (lambda: Line((0, 0), (0.01, 0), -1.0), "duration must be a positive"),
    (lambda: Line((0, math.nan), (0.01, 0), 1.0), "start_point must be a finite"),
    (lambda: Circle((0, 0), 0.0, 0.0, 1.0, 1.0), "radius must be a positive"),
    (lambda: Circle((0, 0), 0.01, 0.0, 0.0, 1.0), "turns"),
    (lambda: Hold((0, 0), math.inf), "duration must be a positive"),
    (lambda: Spline(((0, 0), (0, 0), (0.01, 0)), 1.0), r"0 and 1 coincide at \(0, 0\) m"),
    (lambda: Spline(((0, 0),), 1.0), "at least two"),
    (lambda: Chain(()), "at least one"),
    (lambda: Chain((Line((0, 0), (0.01, 0), 1.0), Hold((0.02, 0), 1.0))), "jump"),
    (lambda: sample(Hold((0, 0), 1.0), 0.0), "step must be a positive"),
])
def test_bad_arguments_raise_clear_errors(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_chain_is_continuous_and_switches_segments_at_the_joins():
    paths = some_paths()
    ref = sample(paths["chain"], STEP)
    assert ref.duration == pytest.approx(2.0 + 0.5 + 5.0 + 0.7)
    assert np.abs(np.diff(ref.x)).max() < 1e-3 and np.abs(np.diff(ref.y)).max() < 1e-3
    k = round(2.2 / STEP)  # inside the first hold
    assert (ref.x[k], ref.y[k]) == (0.02, 0.01) and ref.vx[k] == 0


def test_spline_passes_through_its_points_and_closes():
    # the thesis's random trajectory 2 scaled by 0.8: its (0.038, 0.034) lies outside the disc
    seed = ((-0.01275, 0.04292), (-0.035, -0.009), (0.038, 0.034), (0.0065, -0.0317),
            (-0.025, -0.0335))
    points = tuple((0.8 * x, 0.8 * y) for x, y in seed)
    spline = Spline(points, 15.0)
    ref = sample(spline, STEP)
    path = np.column_stack([ref.x, ref.y])
    for p in points:
        assert np.min(np.linalg.norm(path - p, axis=1)) < 1e-4  # passed within one sample
    first, last = spline.evaluate(np.array([0.0, 15.0])).T
    assert np.allclose(first, last, atol=1e-15)  # periodic: same state after one loop


def test_csv_round_trip(tmp_path):
    ref = thesis_evaluation(STEP)
    ref.to_csv(tmp_path / "ref.csv")
    back = read_csv(tmp_path / "ref.csv", STEP)
    assert len(back.t) == len(ref.t)
    for a, b in zip(ref.signals().values(), back.signals().values()):
        assert np.allclose(a, b, rtol=0, atol=1e-12 * np.abs(a).max())


def test_csv_positions_only_get_smooth_derivatives(tmp_path):
    """A 10 ms table of positions: derivatives by Savitzky-Golay match the analytic ones."""
    path = Circle((0.005, 0.0), 0.02, 0.0, 2.0, 6.0)
    exact = sample(path, STEP)
    coarse = sample(path, 0.01)
    table = np.column_stack([coarse.t, coarse.x, coarse.y])
    np.savetxt(tmp_path / "pos.csv", table, delimiter=",", header="t,x_ref,y_ref", comments="")
    got = read_csv(tmp_path / "pos.csv", STEP)
    assert np.allclose(got.t, exact.t)
    inner = slice(50, -50)  # the filter's ends fit one-sided polynomials
    for name in ("x_ref", "y_ref", "vx_ref", "vy_ref", "ax_ref", "ay_ref"):
        a, b = exact.signals()[name], got.signals()[name]
        assert np.abs(a - b)[inner].max() < 2e-3 * np.abs(a).max(), name


@pytest.mark.parametrize("text, message", [
    ("t,x_ref\n0,0\n1,0\n", "missing column.*y_ref"),
    ("t,x_ref,y_ref\n0,0,0\n1,0,0\n1,0,0\n2,0,0\n",
     r"column time, data row 3 \(line 4\): time does not increase \(t = 1 s, then 1 s\)"),
    ("time,x_ref,y_ref\n0,0,0\n1,nan,0\n2,0,0\n",
     r"column x_ref, data row 2 \(line 3\): NaN or Inf"),
    ("t,x_ref,y_ref\n0,0,0\n1,abc,0\n2,0,0\n",
     r"column x_ref, data row 2 \(line 3\): not a number"),
    ("t,x_ref,y_ref\n0,0,0\n1,0\n2,0,0\n", r"data row 2 \(line 3\) has 2 cells, the header 3"),
    ("t,x_ref,y_ref,x_ref\n0,0,0,0\n1,0,0,0\n", "column x_ref appears 2 times"),
    ("t,x_ref,y_ref\n0,0,0\n1,0.07,0\n2,0,0\n", r"\(0.07, 0\) m lies outside"),
    ("t,x_ref,y_ref\n0,0,0\n0.005,0,0\n", "too short"),
    ("", "empty"),
])
def test_csv_errors(tmp_path, text, message):
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(ValueError, match=message):
        read_csv(tmp_path / "bad.csv", STEP)


def test_csv_with_a_byte_order_mark(tmp_path):
    ref = sample(Line((0.0, 0.0), (0.005, 0.0), 0.5), 0.01)
    ref.to_csv(tmp_path / "plain.csv")
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbf" + (tmp_path / "plain.csv").read_bytes())
    assert np.array_equal(read_csv(tmp_path / "bom.csv", STEP).x,
                          read_csv(tmp_path / "plain.csv", STEP).x)


@pytest.mark.parametrize("content, message", [
    (b"\x89PNG\r\n\x1a\n\x00\x00secret,t,x_ref", "not a CSV text file"),
    (b"t,x_ref,y_ref\n" + b"secret" * 40000, "not a CSV table"),
    (b"t,x_ref,y_ref\n0,0,0\n1,\x00secret,0\n", r"column x_ref, data row 2 \(line 3\): not a"),
    (b"secret,x_ref,y_ref\n0,0,0\n1,0,0\n",
     "missing column.* time: the header row must name time, x_ref, y_ref"),
])
def test_csv_errors_name_the_problem_not_the_content(tmp_path, content, message):
    (tmp_path / "bad.csv").write_bytes(content)
    with pytest.raises(ValueError, match=message) as error:
        read_csv(tmp_path / "bad.csv", STEP)
    assert "secret" not in str(error.value) and "PNG" not in str(error.value)


def test_sampling_beyond_the_available_memory_is_refused_before_allocating(monkeypatch):
    assert available_memory() > 0
    monkeypatch.setattr("flexff.cosim.memory.available_memory", lambda: 500 * 10**6)
    with pytest.raises(MemoryNeeded, match=r"sampling the 15 s reference every 1e-06 s needs "
                                           r"840 MB, more than the 500 MB of memory available"):
        sample(thesis_evaluation_path(), 1e-6)
    assert issubclass(MemoryNeeded, ValueError)


def test_reference_arrays_must_agree():
    with pytest.raises(ValueError, match="equal length"):
        Reference(*[np.zeros(3)] * 6, np.zeros(4))


def test_csv_at_a_coarse_step_fits_its_derivatives_over_five_points_at_least(tmp_path):
    """At a 10 ms step the default 25 ms smoothing window is 3 samples, too few for the cubic
    Savitzky-Golay fit: the window widens to 5 samples, and a parabola's acceleration comes out
    exact."""
    t = np.linspace(0.0, 1.0, 11)
    path = tmp_path / "coarse.csv"
    np.savetxt(path, np.column_stack([t, 0.01 * t**2, 0 * t]), delimiter=",",
               header="time,x_ref,y_ref", comments="")
    reference = read_csv(path, step=0.01)
    assert np.allclose(reference.ax, 0.02, atol=1e-9)
