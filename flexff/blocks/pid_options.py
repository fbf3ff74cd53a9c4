"""The PID block from a run configuration's options: built-ins "pid" (form "series" unless
given) and "pid-gains" (form "parallel" unless given), one block (blocks.pid).

`axes` lists the axes' names, with each per-axis option (blocks.options.PID_PER_AXIS_OPTIONS) a
number for every axis or a table {axis = number}; or it lists one table per axis, {name, unit,
effort_unit, and any per-axis option}. Per axis: crossover_hz with mass (damping, stiffness:
default 0) loop-shape the gains, or kp (ki, kd: default 0; derivative_filter_hz) give them;
notch_hz, lowpass_hz switch the filters on; effort_limit the limit, tracking_gain [1/s] the
back-calculation's gain (default ki / kp). For the block: form, anti_windup (default: by form),
notch_zeta = [z1, z2], lowpass_order (1 | 2, default: by form), lowpass_zeta, position_unit
("m"), effort_unit ("N"); see blocks.pid_design.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, cast

from flexff.blocks import options as opt
from flexff.blocks.loop_shaping import NOTCH_ZETA
from flexff.blocks.pid import pid_system
from flexff.blocks.pid_design import AntiWindup, AxisPid, Form, Gains, LoopShape
from flexff.fmu.errors import InputError
from flexff.fmu.system import System

POSITIVE = {"crossover_hz", "mass", "derivative_filter_hz", "notch_hz", "lowpass_hz",
            "effort_limit"}
AXIS_TABLE_KEYS = ("name", "unit", "effort_unit", *opt.PID_PER_AXIS_OPTIONS)


def pid_from_options(options: Mapping[str, Any], step: float) -> System:
    """The built-in "pid": the PID block, form "series" unless given."""
    return pid_system(axes_from_options(options, step, "series", "pid"), step)


def pid_gains_from_options(options: Mapping[str, Any], step: float) -> System:
    """The built-in "pid-gains": the PID block, form "parallel" unless given."""
    return pid_system(axes_from_options(options, step, "parallel", "pid-gains"), step)


def axes_from_options(options: Mapping[str, Any], step: float, form: Form, block: str
                      ) -> dict[str, AxisPid]:
    """Each axis's AxisPid, by name in order (`form`: the default form)."""
    opt.check_keys(options, opt.PID_OPTIONS, block)
    options, units = _axis_tables(options)
    axes = opt.names(options, "axes")
    values = {k: opt.per_axis(options, k, axes, positive=k in POSITIVE)
              for k in opt.PID_PER_AXIS_OPTIONS}
    if "anti_windup" in options and all(v is None for v in values["effort_limit"].values()):
        raise opt.OptionError("option 'anti_windup' acts at an effort limit: give effort_limit")
    form = cast(Form, _choice(options, "form", opt.PID_FORMS, form))
    anti_windup = cast(AntiWindup | None,
                       _choice(options, "anti_windup", opt.PID_ANTI_WINDUP, None))
    lowpass_order = _choice(options, "lowpass_order", opt.PID_LOWPASS_ORDERS, None)
    notch_zeta, lowpass_zeta = _notch_zeta(options), opt.number(options, "lowpass_zeta",
                                                                 positive=True)
    position = opt.unit(options, "position_unit", "m")
    effort = opt.unit(options, "effort_unit", "N")
    loops = {}
    for a in axes:
        axis = {k: v[a] for k, v in values.items()}
        try:
            loops[a] = AxisPid(
                _gains(axis), notch_hz=axis["notch_hz"], lowpass_hz=axis["lowpass_hz"],
                effort_limit=axis["effort_limit"], tracking_gain=axis["tracking_gain"],
                position_unit=units.get((a, "unit"), position),
                effort_unit=units.get((a, "effort_unit"), effort), form=form,
                anti_windup=anti_windup, notch_zeta=notch_zeta, lowpass_order=lowpass_order,
                lowpass_zeta=lowpass_zeta)
            loops[a].state_space(step)  # the filters' and the design's checks, by axis
        except InputError as error:  # an OptionError, or design_pid's own
            raise opt.OptionError(f"axis {a!r}: {error}") from None
    return loops


def _axis_tables(options: Mapping[str, Any]
                 ) -> tuple[Mapping[str, Any], dict[tuple[str, str], str]]:
    """Options with `axes` as tables turned into names and per-axis tables, and the units."""
    tables = options.get("axes")
    if not isinstance(tables, list) or not any(isinstance(t, Mapping) for t in tables):
        return options, {}
    if not all(isinstance(t, Mapping) for t in tables):
        raise opt.OptionError("option 'axes' must list names or tables {name, ...}, not both")
    merged: dict[str, Any] = {**options, "axes": [t.get("name") for t in tables]}
    units = {}
    for k, table in enumerate(tables):
        unknown = sorted(set(table) - set(AXIS_TABLE_KEYS))
        if unknown:
            raise opt.OptionError(f"axes[{k}].{unknown[0]}: unknown key (known: "
                                  f"{', '.join(AXIS_TABLE_KEYS)})")
        name = opt.name(table, "name")
        for key in ("unit", "effort_unit"):
            if key in table:
                units[name, key] = opt.unit(table, key, "")
    for key in opt.PID_PER_AXIS_OPTIONS:
        given = {t["name"]: t[key] for t in tables if t.get(key) is not None}
        if given and key in options:
            raise opt.OptionError(f"option {key!r} is given in the axis tables and for the "
                                  "block: keep one")
        if given:
            merged[key] = given
    return merged, units


def _gains(axis: Mapping[str, float | None]) -> Gains | LoopShape:
    explicit = [k for k in ("kp", "ki", "kd", "derivative_filter_hz") if axis[k] is not None]
    crossover, mass = axis["crossover_hz"], axis["mass"]
    if crossover is not None:
        if explicit or mass is None:
            raise opt.OptionError("give crossover_hz with mass (and damping, stiffness), or kp, "
                                  "ki, kd, not both" + (": drop " + ", ".join(explicit)
                                                        if explicit else ""))
        return LoopShape(crossover, mass, axis["damping"] or 0.0, axis["stiffness"] or 0.0)
    if axis["kp"] is None:
        raise opt.OptionError("no gains: give crossover_hz and mass, or kp (ki, kd optional)")
    return Gains(axis["kp"], axis["ki"] or 0.0, axis["kd"] or 0.0, axis["derivative_filter_hz"])


def _choice(options: Mapping[str, Any], key: str, choices: Sequence[Any], default: Any) -> Any:
    value = options.get(key, default)
    if value is not None and (isinstance(value, bool) or value not in choices):
        raise opt.OptionError(f"option {key!r} {value!r}: choose one of "
                              f"{', '.join(map(str, choices))}")
    return value


def _notch_zeta(options: Mapping[str, Any]) -> tuple[float, float]:
    zeta = options.get("notch_zeta", NOTCH_ZETA)
    if not (isinstance(zeta, Sequence) and len(zeta) == 2
            and all(isinstance(z, int | float) and not isinstance(z, bool) for z in zeta)):
        raise opt.OptionError(f"option 'notch_zeta' must be two numbers [z1, z2], got {zeta!r}")
    return float(zeta[0]), float(zeta[1])
