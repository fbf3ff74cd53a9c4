"""The manipulator's [reference] kinds of the plane's x, y (plant.paths): circle, line-circle,
spline, segments and csv, each with its table's check and keys, registered by
controllers.manipulator as any machine package registers its kinds (cosim.references).

Every key: "Run configuration", [reference] (docs/reference/configuration.md, generated from
the keys here).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from flexff.cosim.config_keys import Key
from flexff.cosim.references import SMOOTHING_WINDOW, ReferenceKind
from flexff.plant.paths import (
    Chain,
    Circle,
    Line,
    Reference,
    Spline,
    check_workspace,
    read_csv,
    sample,
    segment_chain,
)

if TYPE_CHECKING:
    from flexff.cosim.checks import TableChecker

R = "reference"  # the table the keys are of
CIRCLE = ("circle", "line-circle")
SEGMENT_KEYS = {"line": ("kind", "to", "duration"), "hold": ("kind", "duration"),
                "circle": ("kind", "centre", "turns", "duration"),
                "spline": ("kind", "points", "duration")}
SEGMENT_KINDS = tuple(SEGMENT_KEYS)
SEGMENTS = "reference.segments[k]"

REFERENCE_KEYS: tuple[Key, ...] = (
    Key(R, "radius", "number", "required", "m", "The circle's radius.", CIRCLE),
    Key(R, "centre", "[x, y]", "[0, 0]", "m", "The circle's centre.", CIRCLE),
    Key(R, "turns", "number", "1", "1", "Turns; negative runs clockwise.", CIRCLE),
    Key(R, "start_angle", "number", "0", "rad", "Where on the circle it starts.", CIRCLE),
    Key(R, "duration", "number", "required", "s", "How long the path takes.",
        ("circle", "spline")),
    Key(R, "start", "[x, y]", "[0, 0]", "m", "The starting point.", ("line-circle", "segments")),
    Key(R, "line_duration", "number", "required", "s",
        "The skew-sine line to the circle's start point.", ("line-circle",)),
    Key(R, "circle_duration", "number", "required", "s", "The circle after the line.",
        ("line-circle",)),
    Key(R, "points", "list of [x, y]", "required", "m", "The closed periodic spline's points.",
        ("spline",)),
    Key(R, "segments", "list of tables", "required", "",
        "Segments run in order, each from where the previous one ended.", ("segments",)),
    Key(R, "path", "string", "required", "",
        "A CSV table (columns time, x_ref, y_ref, optionally their velocities and "
        "accelerations), relative to the configuration's folder.", ("csv",)),
    Key(R, "smoothing_window", "number", f"{SMOOTHING_WINDOW:g}", "s",
        "Smoothing of the table's derivatives.", ("csv",)),
)
SEGMENT_TABLE_KEYS: tuple[Key, ...] = (
    Key(SEGMENTS, "kind", "string", "required", "", "line, hold, circle or spline.",
        SEGMENT_KINDS),
    Key(SEGMENTS, "to", "[x, y]", "required", "m", "The line's end point.", ("line",)),
    Key(SEGMENTS, "centre", "[x, y]", "[0, 0]", "m",
        "The circle's centre; radius and start angle follow from the current point.",
        ("circle",)),
    Key(SEGMENTS, "turns", "number", "1", "1", "Turns, not zero; negative runs clockwise.",
        ("circle",)),
    Key(SEGMENTS, "points", "list of [x, y]", "required", "m",
        "A closed spline through the current point, then these.", ("spline",)),
    Key(SEGMENTS, "duration", "number", "required", "s", "How long the segment takes.",
        SEGMENT_KINDS),
)


def _keys_of(kind: str) -> tuple[Key, ...]:
    """The keys of a kind's table (a `segments` reference's segment tables' included)."""
    return (*(k for k in REFERENCE_KEYS if kind in k.kinds),
            *(SEGMENT_TABLE_KEYS if kind == "segments" else ()))


# -- checks: a table -> its options ------------------------------------------------------
def _circle(c: TableChecker, t: Mapping[str, Any]) -> dict[str, Any]:
    return {"centre": c.point(t, R, "centre", (0.0, 0.0)),
            "radius": c.number(t, R, "radius", None, positive=True),
            "turns": c.number(t, R, "turns", 1.0),
            "start_angle": c.number(t, R, "start_angle", 0.0)}


def _check_circle(c: TableChecker, t: Mapping[str, Any]) -> dict[str, Any]:
    c.keys(t, R, ("kind", "centre", "radius", "turns", "start_angle", "duration"))
    return {**_circle(c, t), "duration": c.number(t, R, "duration", None, True)}


def _check_line_circle(c: TableChecker, t: Mapping[str, Any]) -> dict[str, Any]:
    c.keys(t, R, ("kind", "centre", "radius", "turns", "start_angle", "start", "line_duration",
                  "circle_duration"))
    return {**_circle(c, t), "start": c.point(t, R, "start", (0.0, 0.0)),
            "line_duration": c.number(t, R, "line_duration", None, True),
            "circle_duration": c.number(t, R, "circle_duration", None, True)}


def _check_spline(c: TableChecker, t: Mapping[str, Any]) -> dict[str, Any]:
    c.keys(t, R, ("kind", "points", "duration"))
    return {"points": c.points(t, R, "points"),
            "duration": c.number(t, R, "duration", None, True)}


def _check_segments(c: TableChecker, t: Mapping[str, Any]) -> dict[str, Any]:
    c.keys(t, R, ("kind", "start", "segments"))
    start = c.point(t, R, "start", (0.0, 0.0))
    try:
        check_workspace(*start, "the start point")
    except ValueError as error:
        raise c.error("reference.start", str(error)) from None
    return {"start": start, "segments": _segments(c, t)}


def _segments(c: TableChecker, t: Mapping[str, Any]) -> tuple[dict[str, Any], ...]:
    """The checked tables of reference.segments (geometry is checked when built)."""
    specs = t.get("segments")
    if not isinstance(specs, list) or not specs:
        raise c.error("reference.segments", f"expected a list of segment tables, got {specs!r}")
    checked = []
    for k, spec in enumerate(specs):
        where = f"reference.segments[{k}]"
        if not isinstance(spec, dict):
            raise c.error(where, f"expected a table {{kind = ..., ...}}, got {spec!r}")
        kind = c.choice(spec, where, "kind", SEGMENT_KINDS, None)
        c.keys(spec, where, SEGMENT_KEYS[kind])
        values: dict[str, Any] = {"kind": kind}
        if kind == "line":
            values["to"] = c.point(spec, where, "to", None)
        elif kind == "circle":
            values["centre"] = c.point(spec, where, "centre", (0.0, 0.0))
            values["turns"] = c.number(spec, where, "turns", 1.0)
            if values["turns"] == 0:
                raise c.error(f"{where}.turns", "must not be zero")
        elif kind == "spline":
            values["points"] = c.points(spec, where, "points", minimum=2)
        values["duration"] = c.number(spec, where, "duration", None, positive=True)
        checked.append(values)
    return tuple(checked)


def _check_csv(c: TableChecker, t: Mapping[str, Any]) -> dict[str, Any]:
    c.keys(t, R, ("kind", "path", "smoothing_window"))
    return {"path": c.path(t, R, "path"),
            "smoothing_window": c.number(t, R, "smoothing_window", SMOOTHING_WINDOW,
                                         positive=True)}


# -- builds: options, step -> the sampled reference ----------------------------------------
def _build_circle(o: Mapping[str, Any], step: float) -> Reference:
    return sample(_circle_path(o, o["duration"]), step)


def _circle_path(o: Mapping[str, Any], duration: float) -> Circle:
    return Circle(tuple(o["centre"]), o["radius"], o["start_angle"], o["turns"], duration)


def _build_line_circle(o: Mapping[str, Any], step: float) -> Reference:
    circle = _circle_path(o, o["circle_duration"])
    line = Line(tuple(o["start"]), tuple(circle.start), o["line_duration"])
    return sample(Chain((line, circle)), step)


def _build_spline(o: Mapping[str, Any], step: float) -> Reference:
    return sample(Spline(tuple(map(tuple, o["points"])), o["duration"]), step)


def _build_segments(o: Mapping[str, Any], step: float) -> Reference:
    return sample(segment_chain(o["start"], o["segments"]), step)


def _build_csv(o: Mapping[str, Any], step: float) -> Reference:
    ref = read_csv(o["path"], step, o["smoothing_window"])
    return Reference(ref.t - ref.t[0], ref.x, ref.y, ref.vx, ref.vy, ref.ax, ref.ay)


_KINDS: dict[str, tuple[Callable[[Mapping[str, Any], float], Reference],
                        Callable[[TableChecker, Mapping[str, Any]], dict[str, Any]]]] = {
    "circle": (_build_circle, _check_circle),
    "line-circle": (_build_line_circle, _check_line_circle),
    "spline": (_build_spline, _check_spline),
    "segments": (_build_segments, _check_segments),
    "csv": (_build_csv, _check_csv),
}


def plane_kinds() -> tuple[ReferenceKind, ...]:
    """The [reference] kinds of the plane, to register (cosim.references)."""
    return tuple(ReferenceKind(name, build, check, _keys_of(name))
                 for name, (build, check) in _KINDS.items())

