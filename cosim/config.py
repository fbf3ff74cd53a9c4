"""Run configurations: a TOML file parsed and checked into plain dataclasses before anything runs.

Tables and keys (SI units; every table but [reference] may be left out):

  [run]          step (s, default 0.001), stop (s, default: the reference's duration; a longer
                 run holds the reference's last position at rest)
  [reference]    kind = "thesis-eval" | "thesis-hardware-eval" | "circle" | "line-circle" |
                 "spline" | "segments" | "csv", and its keys:
                   thesis-eval: none (the thesis's evaluation reference, sec. 5.7, 15 s)
                   thesis-hardware-eval: none (its evaluation reference on the real machine,
                           sec. 6.6, 100 s)
                   circle: radius, duration, centre = [x, y] (default [0, 0]), turns (default 1,
                           negative runs clockwise), start_angle (rad, default 0)
                   line-circle: a skew-sine line from `start` (default [0, 0]) in line_duration
                           to the circle's start point, then the circle (keys as for circle,
                           with circle_duration instead of duration)
                   spline: points = [[x, y], ...] (closed, periodic), duration
                   segments: start = [x, y] (default [0, 0]) and segments = a list of tables,
                           run in order, each from the point where the previous one ended:
                             {kind = "line", to = [x, y], duration}   skew-sine line
                             {kind = "hold", duration}                at rest
                             {kind = "circle", centre = [x, y] (default [0, 0]), turns
                              (default 1, negative runs clockwise), duration}: radius and start
                              angle follow from the current point and the centre
                             {kind = "spline", points = [[x, y], ...], duration}: one lap of
                              the closed periodic spline through the current point, then the
                              points (its velocity does not start at zero)
                           keys are named `reference.segments[k].key` in errors
                   csv: path (relative to the configuration's folder), smoothing_window (s)
  [plant]        variant = "nominal" | "hardware", seed (encoder noise), and any plant FMU
                 parameter by name (m_up1 = 0.25, noise_std, max_substep, x_start, ...);
                 x_start, y_start default to the reference's first point
  [controller]   crossover_hz, notch (true / false / Hz), encoders (2 or 3); defaults follow
                 the plant variant (controllers.feedback.DEFAULTS)
  [feedforward]  kind = "none" | "model" (rigid-body) | "onnx" (with model = "file.onnx", an
                 exported learned model, and mode = "step" (default) | "precomputed")
  [record]       signals = [names] (default: all), csv (bool, default true)

Any problem (unknown table or key, wrong type, missing file, a reference outside the workspace,
a step that does not divide the stop time, ...) raises ConfigError naming `table.key`.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


from controllers.allocation import ENCODER_CHOICES
from controllers.feedback import OUTPUTS as CONTROLLER_OUTPUTS
from controllers.feedforward import FORCE_OUTPUTS
from controllers.learned_feedforward import model_metadata
from cosim import references
from cosim.references import Reference
from plant.kinematics import check_workspace
from plant.model import VARIANTS, PlantModel
from plant.parameters import NOMINAL
from plant.system import plant_system

REFERENCE_KINDS = ("thesis-eval", "thesis-hardware-eval", "circle", "line-circle", "spline",
                   "segments", "csv")
SEGMENT_KEYS = {"line": ("kind", "to", "duration"), "hold": ("kind", "duration"),
                "circle": ("kind", "centre", "turns", "duration"),
                "spline": ("kind", "points", "duration")}
FEEDFORWARD_KINDS = ("none", "model", "onnx")
FEEDFORWARD_MODES = ("step", "precomputed")
STEP_TOLERANCE = 1e-9  # relative: stop / step must be this close to a whole number
PLANT_EXTRA = ("max_substep",)  # FMU parameters beyond the System's own


class ConfigError(ValueError):
    """A configuration problem, naming the file and the `table.key` at fault."""

    def __init__(self, source: str, key: str, message: str) -> None:
        super().__init__(f"{source}: {key}: {message}")
        self.key = key


@dataclass(frozen=True)
class ReferenceConfig:
    """The reference's kind and its checked keys (paths absolute)."""

    kind: str = "thesis-eval"
    options: Mapping[str, Any] = field(default_factory=dict)

    def build(self, step: float) -> Reference:
        """The reference sampled every `step` seconds from t = 0."""
        o = self.options
        if self.kind == "thesis-eval":
            return references.thesis_evaluation(step)
        if self.kind == "thesis-hardware-eval":
            return references.thesis_hardware_evaluation(step)
        if self.kind == "csv":
            ref = references.read_csv(o["path"], step, o["smoothing_window"])
            return Reference(ref.t - ref.t[0], ref.x, ref.y, ref.vx, ref.vy, ref.ax, ref.ay)
        return references.sample(self._path(), step)

    def _path(self) -> references.Segment:
        o = self.options
        if self.kind == "segments":
            return _segment_chain(o["start"], o["segments"])
        if self.kind == "spline":
            return references.Spline(tuple(map(tuple, o["points"])), o["duration"])
        circle = references.Circle(tuple(o["centre"]), o["radius"], o["start_angle"], o["turns"],
                                   o["duration" if self.kind == "circle" else "circle_duration"])
        if self.kind == "circle":
            return circle
        line = references.Line(tuple(o["start"]), tuple(circle.start), o["line_duration"])
        return references.Chain((line, circle))


class _SegmentError(ValueError):
    """A segment of a `segments` reference that cannot be built; `index` says which."""

    def __init__(self, index: int, message: str) -> None:
        super().__init__(message)
        self.index = index


def _segment_chain(start: tuple[float, float], segments: Sequence[Mapping[str, Any]]
                  ) -> references.Chain:
    """The checked segment tables of a `segments` reference as one Chain from `start`."""
    point, pieces = (float(start[0]), float(start[1])), []
    for k, spec in enumerate(segments):
        try:
            piece = _segment(point, spec)
        except ValueError as error:
            raise _SegmentError(k, str(error)) from None
        pieces.append(piece)
        point = (float(piece.end[0]), float(piece.end[1]))
    return references.Chain(tuple(pieces))


def _segment(point: tuple[float, float], spec: Mapping[str, Any]) -> references.Segment:
    """One segment starting at `point`; circles and splines take their geometry from it."""
    kind, duration = spec["kind"], spec["duration"]
    if kind == "line":
        return references.Line(point, tuple(spec["to"]), duration)
    if kind == "hold":
        return references.Hold(point, duration)
    if kind == "circle":
        centre = spec["centre"]
        dx, dy = point[0] - centre[0], point[1] - centre[1]
        radius = math.hypot(dx, dy)
        if radius == 0:
            raise ValueError(f"the circle starts at its centre {tuple(centre)} m (radius 0): "
                             f"move the centre or the point before it")
        return references.Circle(tuple(centre), radius, math.atan2(dy, dx), spec["turns"],
                                 duration)
    return references.Spline((point, *map(tuple, spec["points"])), duration)


@dataclass(frozen=True)
class PlantConfig:
    variant: str = "nominal"
    parameters: Mapping[str, float] = field(default_factory=dict)
    seed: int | None = None


@dataclass(frozen=True)
class ControllerConfig:
    crossover_hz: float | None = None  # None: the variant's default
    notch: bool | float | None = None  # None: the variant's default; a float is in Hz
    encoders: int = 2


@dataclass(frozen=True)
class FeedforwardConfig:
    kind: str = "none"
    model: Path | None = None
    mode: str = "step"  # onnx: run step by step, or precomputed over the whole reference


@dataclass(frozen=True)
class RecordConfig:
    signals: tuple[str, ...] | None = None  # None: every signal
    csv: bool = True


@dataclass(frozen=True)
class RunConfig:
    """A checked run configuration."""

    name: str
    step: float
    stop: float
    reference: ReferenceConfig
    plant: PlantConfig = PlantConfig()
    controller: ControllerConfig = ControllerConfig()
    feedforward: FeedforwardConfig = FeedforwardConfig()
    record: RecordConfig = RecordConfig()
    source: str = "<config>"

    @property
    def steps(self) -> int:
        return int(round(self.stop / self.step))


def load_config(path: str | Path) -> RunConfig:
    """Read and check a TOML run configuration (relative paths against its folder)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(str(path), "file", "no such configuration file")
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise ConfigError(str(path), "file", f"not valid TOML: {error}") from None
    return parse_config(data, name=path.stem, base=path.resolve().parent, source=str(path))


def parse_config(data: Mapping[str, Any] | str, name: str = "config",
                 base: str | Path = ".", source: str = "<config>") -> RunConfig:
    """Check a configuration given as TOML text or as its parsed tables."""
    if isinstance(data, str):
        try:
            data = tomllib.loads(data)
        except tomllib.TOMLDecodeError as error:
            raise ConfigError(source, "file", f"not valid TOML: {error}") from None
    return _Parser(source, Path(base)).parse(data, name)


class _Parser:
    """Checks one configuration; every error names the file and `table.key`."""

    TABLES = ("run", "reference", "plant", "controller", "feedforward", "record")

    def __init__(self, source: str, base: Path) -> None:
        self.source, self.base = source, base

    def error(self, key: str, message: str) -> ConfigError:
        return ConfigError(self.source, key, message)

    def parse(self, data: Mapping[str, Any], name: str) -> RunConfig:
        for table in data:
            if table not in self.TABLES:
                raise self.error(table, f"unknown table [{table}] (known: "
                                        f"{', '.join(self.TABLES)})")
        tables = {t: self.table(data, t) for t in self.TABLES}
        if "reference" not in data:
            raise self.error("reference", "the [reference] table is required")
        run = tables["run"]
        self.keys(run, "run", ("step", "stop"))
        step = self.number(run, "run", "step", 1e-3, positive=True)
        reference = self.reference(tables["reference"])
        try:
            signal = reference.build(step)
        except _SegmentError as error:
            raise self.error(f"reference.segments[{error.index}]", str(error)) from None
        except (ValueError, OSError) as error:
            given = [f"reference.{k}" for k in tables["reference"] if k != "kind"]
            keys = ", ".join(given) or "reference.kind"
            raise self.error(keys, str(error)) from None
        stop = self.number(run, "run", "stop", signal.duration, positive=True)
        if abs(stop / step - round(stop / step)) > STEP_TOLERANCE * max(1.0, stop / step):
            raise self.error("run.stop", f"{stop!r} s is not a whole number of steps of "
                                         f"{step!r} s (run.step)")
        plant = self.plant(tables["plant"], (float(signal.x[0]), float(signal.y[0])))
        return RunConfig(
            name=name, step=step, stop=stop, reference=reference, plant=plant,
            controller=self.controller(tables["controller"]),
            feedforward=self.feedforward(tables["feedforward"]),
            record=self.record(tables["record"]), source=self.source)

    # -- tables -------------------------------------------------------------------------------
    def reference(self, t: Mapping[str, Any]) -> ReferenceConfig:
        kind = self.choice(t, "reference", "kind", REFERENCE_KINDS, None)
        r = "reference"
        if kind in ("thesis-eval", "thesis-hardware-eval"):
            self.keys(t, r, ("kind",))
            return ReferenceConfig(kind)
        if kind == "csv":
            self.keys(t, r, ("kind", "path", "smoothing_window"))
            return ReferenceConfig(kind, {
                "path": self.path(t, r, "path"),
                "smoothing_window": self.number(t, r, "smoothing_window", 0.025, positive=True)})
        if kind == "segments":
            self.keys(t, r, ("kind", "start", "segments"))
            start = self.point(t, r, "start", (0.0, 0.0))
            try:
                check_workspace(NOMINAL, *start, "the start point")
            except ValueError as error:
                raise self.error("reference.start", str(error)) from None
            return ReferenceConfig(kind, {"start": start, "segments": self.segments(t)})
        if kind == "spline":
            self.keys(t, r, ("kind", "points", "duration"))
            return ReferenceConfig(kind, {"points": self.points(t, r, "points"),
                                          "duration": self.number(t, r, "duration", None, True)})
        circle = {"centre": self.point(t, r, "centre", (0.0, 0.0)),
                  "radius": self.number(t, r, "radius", None, positive=True),
                  "turns": self.number(t, r, "turns", 1.0),
                  "start_angle": self.number(t, r, "start_angle", 0.0)}
        if kind == "circle":
            self.keys(t, r, ("kind", *circle, "duration"))
            return ReferenceConfig(kind, {**circle, "duration": self.number(t, r, "duration",
                                                                            None, True)})
        self.keys(t, r, ("kind", *circle, "start", "line_duration", "circle_duration"))
        return ReferenceConfig(kind, {
            **circle, "start": self.point(t, r, "start", (0.0, 0.0)),
            "line_duration": self.number(t, r, "line_duration", None, True),
            "circle_duration": self.number(t, r, "circle_duration", None, True)})

    def segments(self, t: Mapping[str, Any]) -> tuple[dict[str, Any], ...]:
        """The checked tables of reference.segments (geometry is checked when built)."""
        specs = t.get("segments")
        if not isinstance(specs, list) or not specs:
            raise self.error("reference.segments", f"expected a list of segment tables, got "
                                                   f"{specs!r}")
        checked = []
        for k, spec in enumerate(specs):
            where = f"reference.segments[{k}]"
            if not isinstance(spec, dict):
                raise self.error(where, f"expected a table {{kind = ..., ...}}, got {spec!r}")
            kind = self.choice(spec, where, "kind", tuple(SEGMENT_KEYS), None)
            self.keys(spec, where, SEGMENT_KEYS[kind])
            values: dict[str, Any] = {"kind": kind}
            if kind == "line":
                values["to"] = self.point(spec, where, "to", None)
            elif kind == "circle":
                values["centre"] = self.point(spec, where, "centre", (0.0, 0.0))
                values["turns"] = self.number(spec, where, "turns", 1.0)
                if values["turns"] == 0:
                    raise self.error(f"{where}.turns", "must not be zero")
            elif kind == "spline":
                values["points"] = self.points(spec, where, "points", minimum=2)
            values["duration"] = self.number(spec, where, "duration", None, positive=True)
            checked.append(values)
        return tuple(checked)

    def plant(self, t: Mapping[str, Any], start: tuple[float, float]) -> PlantConfig:
        variant = self.choice(t, "plant", "variant", tuple(VARIANTS), "nominal")
        system = plant_system(variant)
        known = {p.name: p for p in system.parameters}
        self.keys(t, "plant", ("variant", "seed", *known, *PLANT_EXTRA))
        seed = self.integer(t, "plant", "seed", None)
        if seed is not None and not -2**31 <= seed < 2**31:
            raise self.error("plant.seed", f"{seed} does not fit a 32-bit FMI Integer")
        values = {"x_start": start[0], "y_start": start[1]}
        for key in t:
            if key not in ("variant", "seed"):
                positive = key in PLANT_EXTRA or known[key].positive
                values[key] = self.number(t, "plant", key, None, positive=positive)
        physical = {k: v for k, v in values.items()
                    if k not in ("x_start", "y_start", *PLANT_EXTRA)}
        try:
            VARIANTS[variant].parameters.with_values(**physical)
            check_workspace(VARIANTS[variant].parameters, values["x_start"], values["y_start"],
                            "the start position (x_start, y_start)")
        except ValueError as error:
            keys = ", ".join(f"plant.{k}" for k in t if k not in ("variant", "seed")) or "plant"
            raise self.error(keys, str(error)) from None
        return PlantConfig(variant, values, seed)

    def controller(self, t: Mapping[str, Any]) -> ControllerConfig:
        self.keys(t, "controller", ("crossover_hz", "notch", "encoders"))
        notch = t.get("notch")
        if notch is not None and not isinstance(notch, bool):
            notch = self.number(t, "controller", "notch", None, positive=True)
        encoders = self.integer(t, "controller", "encoders", 2)
        if encoders not in ENCODER_CHOICES:
            raise self.error("controller.encoders", f"must be one of {ENCODER_CHOICES}, got "
                                                    f"{encoders}")
        crossover = t.get("crossover_hz")
        if crossover is not None:
            crossover = self.number(t, "controller", "crossover_hz", None, positive=True)
        return ControllerConfig(crossover, notch, encoders)

    def feedforward(self, t: Mapping[str, Any]) -> FeedforwardConfig:
        kind = self.choice(t, "feedforward", "kind", FEEDFORWARD_KINDS, "none")
        if kind != "onnx":
            self.keys(t, "feedforward", ("kind",))
            return FeedforwardConfig(kind)
        self.keys(t, "feedforward", ("kind", "model", "mode"))
        model = self.path(t, "feedforward", "model")
        if model.suffix.lower() != ".onnx":
            raise self.error("feedforward.model", f"{model} is not an .onnx file")
        try:
            model_metadata(model)
        except ValueError as exc:
            raise self.error("feedforward.model", str(exc)) from None
        mode = self.choice(t, "feedforward", "mode", FEEDFORWARD_MODES, "step")
        return FeedforwardConfig(kind, model, mode)

    def record(self, t: Mapping[str, Any]) -> RecordConfig:
        self.keys(t, "record", ("signals", "csv"))
        csv = t.get("csv", True)
        if not isinstance(csv, bool):
            raise self.error("record.csv", f"expected true or false, got {csv!r}")
        if "signals" not in t:
            return RecordConfig(None, csv)
        names = t["signals"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise self.error("record.signals", f"expected a list of signal names, got {names!r}")
        known = all_signals()
        unknown = [n for n in names if n not in known]
        if unknown:
            raise self.error("record.signals", f"unknown signal(s) {unknown} (known: "
                                               f"{', '.join(known)})")
        if len(set(names)) != len(names):
            raise self.error("record.signals", "a signal is listed twice")
        return RecordConfig(tuple(names), csv)

    # -- values -------------------------------------------------------------------------------
    def table(self, data: Mapping[str, Any], name: str) -> Mapping[str, Any]:
        table = data.get(name, {})
        if not isinstance(table, dict):
            raise self.error(name, f"expected a table [{name}], got {table!r}")
        return table

    def keys(self, t: Mapping[str, Any], table: str, allowed: tuple[str, ...]) -> None:
        for key in t:
            if key not in allowed:
                raise self.error(f"{table}.{key}", f"unknown key (known in [{table}]: "
                                                   f"{', '.join(allowed)})")

    def number(self, t: Mapping[str, Any], table: str, key: str, default: float | None,
               positive: bool = False) -> float:
        if key not in t:
            if default is None:
                raise self.error(f"{table}.{key}", "required")
            return default
        value = t[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(f"{table}.{key}", f"expected a number, got {value!r} "
                                               f"({type(value).__name__})")
        if not math.isfinite(value) or (positive and value <= 0):
            raise self.error(f"{table}.{key}", f"must be {'positive and ' if positive else ''}"
                                               f"finite, got {value!r}")
        return float(value)

    def integer(self, t: Mapping[str, Any], table: str, key: str, default: int | None) -> Any:
        value = t.get(key, default)
        if key in t and (isinstance(value, bool) or not isinstance(value, int)):
            raise self.error(f"{table}.{key}", f"expected an integer, got {value!r} "
                                               f"({type(value).__name__})")
        return value

    def choice(self, t: Mapping[str, Any], table: str, key: str, options: tuple[str, ...],
               default: str | None) -> str:
        value = t.get(key, default)
        if value is None:
            raise self.error(f"{table}.{key}", f"required: one of {', '.join(options)}")
        if value not in options:
            raise self.error(f"{table}.{key}", f"unknown {key} {value!r}: choose one of "
                                               f"{', '.join(options)}")
        return value

    def path(self, t: Mapping[str, Any], table: str, key: str) -> Path:
        value = t.get(key)
        if not isinstance(value, str) or not value:
            raise self.error(f"{table}.{key}", f"expected a file path, got {value!r}")
        path = (self.base / value).resolve()
        if not path.is_file():
            raise self.error(f"{table}.{key}", f"no such file: {path}")
        return path

    def point(self, t: Mapping[str, Any], table: str, key: str,
              default: tuple[float, float] | None) -> tuple[float, float]:
        if key not in t and default is None:
            raise self.error(f"{table}.{key}", "required: [x, y] in m")
        value = t.get(key, list(default or ()))
        if not (isinstance(value, list) and len(value) == 2 and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value)):
            raise self.error(f"{table}.{key}", f"expected [x, y] in m, got {value!r}")
        return float(value[0]), float(value[1])

    def points(self, t: Mapping[str, Any], table: str, key: str, minimum: int = 3) -> tuple:
        value = t.get(key)
        if not isinstance(value, list) or len(value) < minimum:
            raise self.error(f"{table}.{key}", f"expected at least {minimum} [x, y] points, got "
                                               f"{value!r}")
        return tuple(self.point({key: v}, table, key, (0.0, 0.0)) for v in value)


def all_signals() -> tuple[str, ...]:
    """Every signal a run can record, in the order recordings list them."""
    return (*Reference.SIGNALS, *(v.name for v in FORCE_OUTPUTS),
            *(v.name for v in CONTROLLER_OUTPUTS), *PlantModel.output_names)


EXAMPLES = {
    "thesis-eval-pid": """\
# PID alone on the thesis's evaluation reference (sec. 5.7: a line, then 11.5 circles in 12 s),
# nominal plant, 15 s.
[run]
step = 0.001
stop = 15.0

[reference]
kind = "thesis-eval"

[plant]
variant = "nominal"

[controller]
encoders = 2          # crossover_hz and notch follow the plant variant unless given

[feedforward]
kind = "none"

[record]
# signals = ["x_ref", "y_ref", "x", "y"]   # default: every signal
csv = true
""",
    "thesis-eval-model-ff": """\
# The thesis's evaluation reference with the rigid-body feedforward of the nominal model,
# nominal plant, 15 s.
[run]
step = 0.001
stop = 15.0

[reference]
kind = "thesis-eval"

[plant]
variant = "nominal"

[feedforward]
kind = "model"
""",
    "hardware-circle-pid": """\
# The "hardware" plant (mismatch, friction, parasitic mode, encoder noise) under PID with its
# notch, on a line from the centre and two turns of a 20 mm circle; 1 s at rest at the end.
[run]
step = 0.001
stop = 11.0

[reference]
kind = "line-circle"
start = [0.0, 0.0]
line_duration = 2.0
centre = [0.0, 0.0]
radius = 0.02
turns = 2.0
circle_duration = 8.0

[plant]
variant = "hardware"
seed = 1

[controller]
notch = true
""",
    "hardware-thesis-eval-model-ff": """\
# The rigid-body feedforward of the nominal model on the hardware plant, along the thesis's
# evaluation reference for the real machine: what model mismatch and friction leave for a
# learned feedforward to remove.
[reference]
kind = "thesis-hardware-eval"

[plant]
variant = "hardware"
seed = 1

[feedforward]
kind = "model"
""",
    "line-hold-circle": """\
# The thesis's hardware evaluation path (sec. 6.6; kind = "thesis-hardware-eval" names it) as
# segments, 100 s on the hardware plant under PID: a skew-sine line from the centre to
# (8.2, 8.2) mm in 21 s, 1 s at rest, 9 turns in 75 s (0.12 Hz) about the centre, which makes
# the radius 11.6 mm and passes through the line's end, then 3 s at rest.
[reference]
kind = "segments"
start = [0.0, 0.0]
segments = [
    {kind = "line", to = [0.0082, 0.0082], duration = 21.0},
    {kind = "hold", duration = 1.0},
    {kind = "circle", centre = [0.0, 0.0], turns = 9.0, duration = 75.0},
    {kind = "hold", duration = 3.0},
]

[plant]
variant = "hardware"
seed = 1
""",
    "spline-model-ff": """\
# A closed periodic spline through four points in 6 s, from rest at its first point.
[run]
stop = 6.0

[reference]
kind = "spline"
points = [[0.0, 0.0], [0.02, 0.015], [0.0, 0.03], [-0.02, 0.015]]
duration = 6.0

[feedforward]
kind = "model"
""",
}


def config_examples() -> dict[str, str]:
    """Example configurations (TOML text) by name."""
    return dict(EXAMPLES)
