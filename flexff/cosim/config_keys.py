"""Every key of a run configuration's general form, as data: name, type, default, unit, meaning.

The documentation's configuration reference is rendered from `all_keys()` (KEYS and the keys
of the [reference] kinds machine packages register, cosim.references), and a test checks it
against the keys that cosim.config's parser and cosim.machine accept. Built-in FMUs' options
come from their registry (cosim.builtins), not from here.
"""

from __future__ import annotations

from dataclasses import dataclass

from flexff.cosim.axis_references import AXIS_KINDS
from flexff.fmu.defaults import DEFAULT_STEP


@dataclass(frozen=True)
class Key:
    """One key of one table; `kinds`: the table's `kind` (or form) values it belongs to."""

    table: str
    name: str
    type: str
    default: str
    unit: str
    meaning: str
    kinds: tuple[str, ...] = ()


KEYS: tuple[Key, ...] = (
    # [run]
    Key("run", "step", "number", f"{DEFAULT_STEP:g}", "s", "The communication step."),
    Key("run", "start", "number", "first FMU's default experiment, else 0", "s",
        "The start time. Point k is at start + k * step."),
    Key("run", "stop", "number", "start + the reference's duration, else the first FMU's "
        "default experiment", "s", "The end time, as in FMI. The run lasts stop - start, "
        "a whole number of steps."),
    Key("run", "tolerance", "number", "each FMU's default experiment", "1",
        "Relative tolerance of every FMU's own solver."),
    Key("run", "step_timeout", "number", "60", "s",
        "Bound on each call of an FMU in its own process, instantiating and each step included "
        "(needs isolate)."),
    Key("run", "algorithm", "string", '"gauss-seidel"', "",
        'The master algorithm: "gauss-seidel" or "jacobi".'),
    Key("run", "order", "list of strings", "the order of the [fmu.*] tables", "",
        "Every FMU name once, in stepping order."),
    Key("run", "allow_nonfinite", "boolean", "false", "",
        "Let every FMU's NaN or infinite outputs and parameters through."),
    # [reference]
    Key("reference", "kind", "string", "required", "",
        "point-to-point, sine, multisine, random (every axis of the [machine]), or a kind a "
        "machine package registers (its keys below, by kind)."),
    Key("reference", "duration", "number", "required", "s", "How long the path takes.",
        AXIS_KINDS),
    Key("reference", "seed", "integer", "0", "", "The random draws' seed (each axis its own).",
        AXIS_KINDS),
    Key("reference", "share", "number", "0.8", "1",
        "The share of each axis's velocity, acceleration and jerk limits reached at most.",
        AXIS_KINDS),
    Key("reference", "start", "table: axis = number", "the range's centre", "axis unit",
        "Where each axis starts; sine, multisine and random move to the centre first.",
        AXIS_KINDS),
    Key("reference", "points", "table: axis = [numbers]", "random points of the range",
        "axis unit", "The positions each axis moves to, in turn.", ("point-to-point",)),
    Key("reference", "rest", "number", "0.2", "s", "The hold before each move and after the "
        "last.", ("point-to-point",)),
    Key("reference", "frequency_hz", "number, or table: axis = number",
        "where the range's amplitude meets the limits", "Hz", "The sine's frequency.",
        ("sine",)),
    Key("reference", "bandwidth_hz", "number, or table: axis = number",
        "where the range's amplitude meets the limits", "Hz",
        "The random path's points per second.", ("random",)),
    # [[source]]
    Key("source", "kind", "string", "required", "", '"constant" or "csv".',
        ("constant", "csv")),
    Key("source", "values", "table", "required", "",
        "Constant signals: {name = number, ...}.", ("constant",)),
    Key("source", "path", "string", "required", "",
        "A CSV table: header `time,<name>,...`, interpolated onto the step.", ("csv",)),
    # [fmu.NAME]
    Key("fmu.NAME", "path", "string", "path or builtin", "",
        "Any FMI 2.0 or 3.0 FMU, relative to the configuration.", ("path",)),
    Key("fmu.NAME", "builtin", "string", "path or builtin", "",
        "A registered built-in FMU; its options are keys of this table.", ("builtin",)),
    Key("fmu.NAME", "parameters", "table", "{}", "",
        "Start values of parameters or inputs, checked against the FMU's variables.",
        ("path", "builtin")),
    Key("fmu.NAME", "unconnected", "string", '"error"', "",
        '"error", or "start": unconnected inputs keep their start values.',
        ("path", "builtin")),
    Key("fmu.NAME", "tolerance", "number", "[run] tolerance, else the default experiment",
        "1", "Relative tolerance of this FMU's own solver.", ("path", "builtin")),
    Key("fmu.NAME", "allow_nonfinite", "boolean", "[run] allow_nonfinite", "",
        "Let this FMU's NaN or infinite outputs and parameters through."),
    Key("fmu.NAME", "isolate", "boolean", "false", "",
        "Run the FMU in its own process: a crash or hang ends the run with an error.",
        ("path", "builtin")),
    Key("fmu.NAME", "sandbox", "boolean", "true", "",
        "An isolated FMU runs in a sandbox: no network, no new process, writes only to its "
        "scratch folder (needs isolate).", ("path", "builtin")),
    Key("fmu.NAME", "sandbox_memory", "number", "4096", "MB",
        "The sandboxed FMU's private writable memory (needs isolate).", ("path", "builtin")),
    Key("fmu.NAME", "sandbox_cpu", "number", "none", "s",
        "The sandboxed FMU's CPU time (needs isolate).", ("path", "builtin")),
    Key("fmu.NAME", "sandbox_scratch", "number", "1024", "MB",
        "What the sandboxed FMU's scratch folder holds (needs isolate).", ("path", "builtin")),
    Key("fmu.NAME", "sandbox_read", "list of paths", "everything", "",
        "Confine the sandboxed FMU's reads to its own folder, the system's libraries and these "
        "paths (needs isolate).", ("path", "builtin")),
    Key("fmu.NAME", "fmi", "integer", "2", "",
        "The FMI version a built-in is built in: 2 or 3 (3.0, bit-equal to 2.0).",
        ("builtin",)),
    Key("fmu.NAME", "feedthrough", "boolean", "true (as the FMU's model structure says)", "",
        "false: no output depends directly on an input (an FMU that declares no output "
        "dependencies, which FMI reads as every input, but whose outputs are positions or "
        "states), so Gauss-Seidel may step it first; refused for an FMU that declares one "
        "that does.", ("path",)),
    Key("fmu.NAME", "solver", "string", "none (co-simulation)", "",
        '"cvode": run the FMU as model exchange.', ("path",)),
    Key("fmu.NAME", "scheduled", "boolean", "false (true for an FMU with that interface alone)",
        "", "Run an FMI 3.0 FMU through scheduled execution: each step, the partitions of its "
        "periodic input clocks that tick, in priority order.", ("path",)),
    Key("fmu.NAME", "strict", "boolean", "false", "",
        "Refuse the FMU for description faults that change no run too (an FMU with them "
        "runs with one warning; faults that would make a run wrong always stop it).",
        ("path",)),
    # [[connection]]
    Key("connection", "from", "string", "required", "", '"fmu.output" or a source signal.'),
    Key("connection", "to", "string", "required", "", '"fmu.input".'),
    Key("connection", "gain", "number", "1", "1", "to = gain * from + offset."),
    Key("connection", "offset", "number", "0", "the input's", "to = gain * from + offset."),
    # [record]
    Key("record", "signals", "list of strings", "all", "", "The signals to record."),
    Key("record", "csv", "boolean", "false", "", "Also write signals.csv."),
    Key("record", "plot", "boolean", "true where the run tracks an axis", "",
        "Draw the plots (signals.png for a run that tracks none)."),
    Key("record", "every", "integer", "1", "", "Keep every N-th point (metrics see them all)."),
    # [machine]
    Key("machine", "name", "string", "required", "", "The machine's name."),
    Key("machine", "axis", "list of tables", "required", "", "The axes ([[machine.axis]])."),
    Key("machine", "prior", "table", "all default terms", "",
        "The identified model's terms ([machine.prior])."),
    Key("machine", "log", "table", "the dataset's own names", "",
        "How the machine's logs name its signals ([machine.log])."),
    Key("machine", "exact", "table", "{}", "",
        'Start values ("instance.parameter" = number) with which the loop measures exactly, '
        "such as an encoder's resolution at 0: ILC and evaluate measure the noise floor with "
        "them."),
    Key("machine", "ilc", "table", "ILC's defaults", "",
        "Iterative learning control's settings on this loop ([machine.ilc])."),
    Key("machine", "learning", "table", "derived from the data", "",
        "The preprocessing of features and labels ([machine.learning])."),
    Key("machine.axis", "name", "string", "required", "",
        "A letter, then letters or digits; names <axis>_ref, v<axis>_ref, ..."),
    Key("machine.axis", "unit", "string", '"m"', "", "The axis's position unit."),
    Key("machine.axis", "measured", "string", "required where a loop is run", "",
        '"instance.variable" (FMI names too: plant.pos[1], plant.der(x), plant.\'my var\'), '
        "or an expression of outputs (a kinematic map)."),
    Key("machine.axis", "true", "string", "none", "",
        "The true position a simulation gives; only the metrics read it."),
    Key("machine.axis", "feedforward", "string", "required where a loop is run", "",
        "The FMU input the feedforward drives."),
    Key("machine.axis", "effort", "string", "required where a loop is run", "",
        "The output the controller commands: the labels."),
    Key("machine.axis", "effort_unit", "string", '"N"', "", "The effort's unit."),
    Key("machine.axis", "range", "[low, high]", "required", "axis unit",
        "The excitation's position range."),
    Key("machine.axis", "velocity", "number", "required", "axis unit/s",
        "The excitation's bound on |velocity|."),
    Key("machine.axis", "acceleration", "number", "required", "axis unit/s^2",
        "The excitation's bound on |acceleration|."),
    Key("machine.axis", "jerk", "number", "none", "axis unit/s^3",
        "The excitation's bound on |jerk|."),
    Key("machine.prior", "terms", "list of strings",
        '["inertia", "viscous", "coulomb", "offset"]', "",
        "inertia, viscous, coulomb, coulomb_asymmetric, offset."),
    Key("machine.prior", "extra", "table", "{}", "",
        'Per axis, term = "expression" of the axes\' x, vx, ax.'),
    Key("machine.prior", "coulomb_width", "number", "chosen by the identification",
        "axis unit/s", "The width of the friction's tanh."),
    Key("machine.log", "time", "string", '"time"', "", "The log's time column [s]."),
    Key("machine.log", "scalars", "table", "{}", "", "Named numbers for the expressions."),
    Key("machine.log", "columns", "table", "{}", "",
        "Dataset signal = expression of the log's columns and scalars."),
    Key("machine.ilc", "iterations", "integer", "10", "",
        "Learning trials after PID alone (flexff ilc --iterations, evaluate --ilc-iterations)."),
    Key("machine.ilc", "cutoff_hz", "number", "0.15 times the rate", "Hz",
        "The corner of the learning filter's zero-phase low-pass Q (--cutoff, "
        "--ilc-cutoff)."),
    Key("machine.ilc", "gain", "number", "1", "",
        "The learning gain on the model's correction P^-1 e; below 1 learns more slowly but "
        "tolerates a worse model (--gain, --ilc-gain)."),
    Key("machine.ilc", "model", "string", "identified on trial 0", "",
        "The learning filter's inverse model: a name a machine package registers (a short "
        "form's own, `flexff config expand` shows it); by default the prior's linear model "
        "identified on PID alone."),
    Key("machine.ilc", "seed", "string", "none", "",
        "\"instance.name\": the option or parameter that seeds the loop's noise, set anew "
        "each trial so that the iteration learns what repeats, not one noise sequence."),
    Key("machine.learning", "cutoff_hz", "number",
        "4x the band of 99 % of the references' velocity energy, at most 5 % of the rate", "Hz",
        "The labels' zero-phase Butterworth low-pass corner (the measured motion's: 8x it)."),
    Key("machine.learning", "filter_order", "integer", "4", "",
        "The order of that low-pass (1 to 12)."),
    Key("machine.learning", "lead_s", "number", "half a sample (the zero-order hold's)", "s",
        "How far each effort is taken before the motion it is compared with."),
    Key("machine.learning", "model_rate_hz", "number",
        "the data rate over a whole number, at least 10x cutoff_hz", "Hz",
        "The rate the labels are decimated to and the models run at."),
)

TABLES = ("run", "reference", "source", "fmu.NAME", "connection", "record", "machine",
          "machine.axis", "machine.prior", "machine.log", "machine.ilc", "machine.learning")


def all_keys() -> tuple[Key, ...]:
    """KEYS and, after [reference]'s, the keys of the registered [reference] kinds, each
    once."""
    from flexff.cosim.references import reference_kinds  # loads the machine packages

    registered = tuple(dict.fromkeys(k for kind in reference_kinds().values()
                                     for k in kind.keys))
    last = max(i for i, k in enumerate(KEYS) if k.table == "reference")
    return (*KEYS[:last + 1], *registered, *KEYS[last + 1:])


def tables() -> tuple[str, ...]:
    """The tables of all_keys(), in order (TABLES and the registered kinds' lists of tables,
    `reference.LIST[k]`, after [reference])."""
    found = tuple(dict.fromkeys(k.table for k in all_keys()))
    extra = tuple(t for t in found if t not in TABLES)
    at = TABLES.index("reference") + 1
    return (*TABLES[:at], *extra, *TABLES[at:])


def keys_of(table: str, kind: str | None = None) -> tuple[str, ...]:
    """The names of `table`'s keys (for `kind`, if given), in the order of all_keys(), each
    once."""
    return tuple(dict.fromkeys(k.name for k in all_keys() if k.table == table and (
        kind is None or not k.kinds or kind in k.kinds)))
