"""The `segments` reference kind of run configurations: pieces chained end to start, durations
that add up, circles and splines that take their geometry from the current point, and errors
that name the segment and key at fault."""

import math

import numpy as np
import pytest

from flexff.cosim.config import ConfigError, config_examples, parse_config
from flexff.cosim.references import build_reference

STEP = 1e-3
SEGMENTS = [
    {"kind": "line", "to": [0.01, -0.005], "duration": 1.5},
    {"kind": "hold", "duration": 0.5},
    {"kind": "circle", "centre": [0.002, 0.0], "turns": -1.25, "duration": 2.0},
    {"kind": "spline", "points": [[0.0, 0.015], [-0.012, 0.0]], "duration": 3.0},
]


def build(segments, start=(0.002, 0.003)):
    config = parse_config({"reference": {"kind": "segments", "start": list(start),
                                         "segments": segments}})
    return config, build_reference(config.reference.kind, config.reference.options, STEP)


def index(t):
    return round(t / STEP)


def test_segments_chain_end_to_start_and_durations_add_up():
    config, ref = build(SEGMENTS)
    assert config.stop == pytest.approx(7.0) and ref.t[-1] == pytest.approx(7.0)
    assert config.builtin("plant").parameters == {"x_start": 0.002, "y_start": 0.003}
    xy = np.vstack([ref.x, ref.y])
    # positions are continuous everywhere: no step moves further than the top speed allows
    speed = np.hypot(ref.vx, ref.vy).max()
    assert np.abs(np.diff(xy, axis=1)).max() <= speed * STEP * 1.01
    # the line ends at rest at its point, the hold stays there
    line_end, hold_end = index(1.5), index(2.0)
    np.testing.assert_allclose(xy[:, line_end:hold_end + 1].T, [[0.01, -0.005]] * 501, atol=1e-15)
    assert np.abs(ref.vx[line_end:hold_end + 1]).max() < 1e-12
    # the circle: radius from its start point to the centre, clockwise for negative turns
    circle = slice(hold_end, index(4.0) + 1)
    radius = np.hypot(ref.x[circle] - 0.002, ref.y[circle] + 0.0)
    np.testing.assert_allclose(radius, math.hypot(0.008, -0.005), rtol=1e-12)
    angle = np.unwrap(np.arctan2(ref.y[circle], ref.x[circle] - 0.002))
    assert angle[-1] - angle[0] == pytest.approx(-1.25 * 2 * math.pi, rel=1e-9)
    # the spline: a closed loop through the circle's end point and the given points
    spline_start = xy[:, index(4.0)]
    np.testing.assert_allclose(xy[:, -1], spline_start, atol=1e-12)
    for point in ([0.0, 0.015], [-0.012, 0.0]):
        assert np.hypot(*(xy[:, index(4.0):] - np.array(point)[:, None])).min() < 1e-4


def test_spline_laps_repeat_the_same_loop():
    _, ref = build([{"kind": "spline", "points": [[0.01, 0.01], [-0.01, 0.005]],
                     "duration": 2.0}] * 2, start=(0.0, -0.01))
    first, second = ref.x[:index(2.0) + 1], ref.x[index(2.0):]
    np.testing.assert_allclose(first, second, atol=1e-15)


def test_line_hold_circle_example():
    config = parse_config(config_examples()["line-hold-circle"])
    assert config.stop == pytest.approx(100.0)
    assert config.builtin("plant").options["variant"] == "hardware"
    ref = build_reference(config.reference.kind, config.reference.options, STEP)
    np.testing.assert_allclose([ref.x[index(21.0)], ref.y[index(21.0)]], [0.0082, 0.0082],
                               atol=1e-15)
    circle = slice(index(22.0), index(97.0) + 1)
    np.testing.assert_allclose(np.hypot(ref.x[circle], ref.y[circle]), 0.0082 * math.sqrt(2),
                               rtol=1e-12)  # 11.6 mm, through the line's end
    assert ref.x[0] == ref.y[0] == 0.0 and np.hypot(ref.vx[-3000:], ref.vy[-3000:]).max() == 0


def test_thesis_hardware_eval_kind_is_the_segment_example():
    """The named reference (cosim.references) and the segments written out in TOML agree."""
    named = parse_config({"reference": {"kind": "thesis-hardware-eval"}})
    segments = parse_config(config_examples()["line-hold-circle"])
    assert named.stop == segments.stop == pytest.approx(100.0)
    a, b = (build_reference(c.reference.kind, c.reference.options, STEP)
            for c in (named, segments))
    for signal in ("t", "x", "y", "vx", "vy", "ax", "ay"):
        np.testing.assert_allclose(getattr(a, signal), getattr(b, signal), rtol=0, atol=1e-15)


@pytest.mark.parametrize("segments, key, message", [
    ([], "reference.segments", "expected a list of segment tables"),
    ([3], "reference.segments[0]", "expected a table"),
    ([{"duration": 1.0}], "reference.segments[0].kind", "required"),
    ([{"kind": "arc", "duration": 1.0}], "reference.segments[0].kind", "unknown kind 'arc'"),
    ([{"kind": "hold", "duration": 1.0}, {"kind": "line", "to": [0.01, 0]}],
     "reference.segments[1].duration", "required"),
    ([{"kind": "hold", "duration": -1.0}], "reference.segments[0].duration", "must be positive"),
    ([{"kind": "hold", "duration": "1 s"}], "reference.segments[0].duration", "expected a number"),
    ([{"kind": "line", "duration": 1.0}], "reference.segments[0].to", "required"),
    ([{"kind": "line", "to": [0.01], "duration": 1.0}], "reference.segments[0].to",
     "expected [x, y]"),
    ([{"kind": "hold", "to": [0, 0], "duration": 1.0}], "reference.segments[0].to",
     "unknown key"),
    ([{"kind": "hold", "duration": 1.0}, {"kind": "circle", "radius": 0.01, "duration": 1.0}],
     "reference.segments[1].radius", "unknown key"),
    ([{"kind": "circle", "centre": [0.01, 0.0], "turns": 0, "duration": 1.0}],
     "reference.segments[0].turns", "must not be zero"),
    ([{"kind": "spline", "points": [[0.01, 0.0]], "duration": 1.0}],
     "reference.segments[0].points", "at least 2"),
])
def test_mistakes_name_the_segment_key(segments, key, message):
    with pytest.raises(ConfigError) as info:
        build(segments)
    assert f": {key}: " in str(info.value) and message in str(info.value)


@pytest.mark.parametrize("segments, key, message", [
    ([{"kind": "hold", "duration": 1.0}, {"kind": "line", "to": [0.04, 0.04], "duration": 1.0}],
     "reference.segments[1]", "outside the workspace"),
    ([{"kind": "line", "to": [0.03, 0.0], "duration": 1.0},
      {"kind": "circle", "centre": [0.0, 0.0], "duration": 1.0},
      {"kind": "circle", "centre": [-0.015, 0.0], "duration": 1.0}],
     "reference.segments[2]", "outside the workspace"),
    ([{"kind": "spline", "points": [[0.05, 0.02], [0.0, 0.03]], "duration": 2.0}],
     "reference.segments[0]", "outside the workspace"),
    ([{"kind": "hold", "duration": 1.0},
      {"kind": "circle", "centre": [0.002, 0.003], "duration": 1.0}],
     "reference.segments[1]", "radius 0"),
    ([{"kind": "spline", "points": [[0.01, 0.0], [0.01, 0.0]], "duration": 2.0}],
     "reference.segments[0]", "coincide"),
])
def test_geometry_errors_name_the_segment(segments, key, message):
    with pytest.raises(ConfigError) as info:
        build(segments)
    assert f": {key}: " in str(info.value) and message in str(info.value)


def test_a_start_outside_the_workspace():
    with pytest.raises(ConfigError, match=r": reference.start: .*outside the workspace"):
        build([{"kind": "hold", "duration": 1.0}], start=(0.05, 0.01))
    with pytest.raises(ConfigError, match=r": reference.start: expected \[x, y\]"):
        parse_config({"reference": {"kind": "segments", "start": "centre",
                                    "segments": [{"kind": "hold", "duration": 1.0}]}})
    with pytest.raises(ConfigError, match=r": reference.radius: unknown key"):
        parse_config({"reference": {"kind": "segments", "radius": 0.01,
                                    "segments": [{"kind": "hold", "duration": 1.0}]}})
