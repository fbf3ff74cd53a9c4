"""The evaluation report of `flexff evaluate`: flexff's version of the thesis's Tables 5.2 / 6.2.

It compares the scenarios' tracking errors with each other, with the ILC limit and with the
thesis's published numbers, and writes summary.json, table.md, paths.png, errors.png and
forces.png. Where the loop has a noise floor, each axis also gets the feedforward's own share
of e2 (cosim.metrics.own_share).

Docs: "File formats", section An evaluation folder (docs/reference/file-formats.md), and "ILC
and the noise floor", section The own share (docs/explanation/ilc-noise-floor.md).
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from flexff.cosim.metrics import named_axes, own_share, tracking_metrics
from flexff.cosim.plots import MM, save_figure
from flexff.cosim.recording import Recording, atomic_write
from flexff.fmu.errors import InputError
from flexff.learning.force_gap import band_names, force_gap
from flexff.learning.machine_loop import feedforward_signal
from flexff.plant.signals import (
    AXES,
    FEEDBACK_FORCES,
    FEEDFORWARD_FORCES,
    POSITION_REFERENCE,
    TRUE_POSITION,
    names,
)

SCENARIO_LABELS: dict[str, str] = {
    "pid": "PID alone",
    "rigid-body": "rigid-body FF",
    "identified": "identified rigid-body FF",
    "lstm": "LSTM FF",
    "cnn-lstm": "CNN-LSTM FF",
    "tcn": "TCN FF",
    "pgnn": "physics-guided FF",
    "limit": "ILC limit",
    # current-level models (learning.evaluate's KIND-currents): their feedforward acts after
    # the control allocation, so the forces figure shows no F_ff for them
    "lstm-currents": "LSTM current FF",
    "cnn-lstm-currents": "CNN-LSTM current FF",
    "tcn-currents": "TCN current FF",
    "pgnn-currents": "physics-guided current FF",
}
# black-box networks with the identified rigid-body force as inputs (learning.evaluate's
# KIND-force)
SCENARIO_LABELS.update({f"{name}-force": f"{SCENARIO_LABELS[name]} on identified force"
                        for name in ("lstm", "cnn-lstm", "tcn")})
# models trained on the force ILC learned on each training reference (learning.evaluate's
# KIND-ilc and KIND-force-ilc, and its identified-ilc)
SCENARIO_LABELS.update({f"{name}-ilc": f"{SCENARIO_LABELS[name]} (ILC labels)"
                        for name in ("identified", "lstm", "cnn-lstm", "tcn", "pgnn",
                                     "lstm-force", "cnn-lstm-force", "tcn-force")})
LIMIT = "limit"  # the scenario of iterative learning control's force (learning.ilc)
PER_LIMIT = "e2_per_limit"  # a scenario's e2 / the limit's
OWN = "own_e2"  # a scenario's own share of e2 over the noise floor: sqrt(e2^2 - floor^2)
AT_FLOOR = "at_floor"  # True where a scenario's e2 <= the noise floor (its own share is 0)


def _thesis(exponent: int, rows: Mapping[str, tuple[float, float, float, float]]
            ) -> dict[str, Any]:
    """A thesis table in SI units from its printed rows (‖E_x‖₂, ‖E_y‖₂, ‖E_x‖∞, ‖E_y‖∞), which
    are in units of 10**exponent; read as decimal literals so 42.930 x 1e-4 is 0.004293.

    The thesis's ‖E‖₂ is stored as "rms": its values are the rms error, not flexff's e2 =
    rms / sqrt(T). Read as e2, its PID alone in simulation (42.93e-4 over 15 s) would be an rms
    of 16.6 mm, above its own largest error of 14.2 mm; read as the rms it is 4.29 mm, next to
    flexff's 3.85 mm on the same reference."""
    def si(value: float) -> float:
        return float(f"{value!r}e{exponent}")

    return {name: {"x": {"rms": si(rms_x), "einf": si(einf_x)},
                   "y": {"rms": si(rms_y), "einf": si(einf_y)}}
            for name, (rms_x, rms_y, einf_x, einf_y) in rows.items()}


# ‖E‖₂ (the rms) and ‖E‖∞ in m, as printed (x 1e-4 in Table 5.2, x 1e-3 in Table 6.2)
THESIS_TABLES: dict[str, dict[str, Any]] = {
    "sim": _thesis(-4, {"pid": (42.930, 42.940, 142.23, 140.00),
                        "lstm": (0.457, 1.102, 3.467, 4.032),
                        "cnn-lstm": (10.550, 16.648, 42.146, 72.34),
                        "tcn": (1.257, 1.367, 5.861, 6.372)}),
    "hardware": _thesis(-3, {"pid": (3.585, 3.517, 7.82, 8.24),
                             "lstm": (1.985, 2.624, 5.15, 6.952),
                             "tcn": (1.742, 3.446, 4.736, 9.361)}),
}

# env -> (the thesis table's scale as a power of ten, which table and what it measured)
_ENVS = {"sim": (-4, "thesis Table 5.2 (nominal simulation)"),
         "hardware": (-3, "thesis Table 6.2 (the real machine)")}
NORMS = ("rms", "e2", "einf")
_ROWS = (("rms", "x", "‖E_x‖₂ (rms, as the thesis)"),
         ("rms", "y", "‖E_y‖₂ (rms, as the thesis)"),
         ("e2", "x", "e2 x (rms/√T)"), ("e2", "y", "e2 y (rms/√T)"),
         ("einf", "x", "‖E_x‖∞"), ("einf", "y", "‖E_y‖∞"))
UNITS = {"rms": "m", "e2": "m/sqrt(s)", "einf": "m",
         **{f"{norm}_ratio": "PID alone / scenario" for norm in NORMS},
         PER_LIMIT: "scenario / ILC limit",
         OWN: "m/sqrt(s): sqrt(e2^2 - noise_floor^2), 0 where e2 <= noise_floor",
         AT_FLOOR: "e2 <= noise_floor",
         "force_gap": "N and s: the ILC limit's force minus the scenario's (learning.force_gap)"}
TRACKING = names(POSITION_REFERENCE, TRUE_POSITION)
FEEDBACK = names(FEEDBACK_FORCES)


def feedforward_name(rec: Recording, axis: int) -> str:
    """The signal of the feedforward force on `axis` (0: x, 1: y) as the controller received
    it: the force table's `<axis>_ff` where one fed it (learning.machine_loop, as the LIMIT
    scenario and ILC's trials run), else the feedforward's Fx_ff, Fy_ff."""
    table = feedforward_signal(AXES[axis])
    return table if table in rec.signals else names(FEEDFORWARD_FORCES)[axis]


def feedforward_of(rec: Recording, axis: int) -> np.ndarray:
    """The feedforward force on `axis` (feedforward_name); KeyError where the run has none."""
    return rec.signals[feedforward_name(rec, axis)]


def _check_env(env: str) -> None:
    if env not in _ENVS:
        raise InputError(f"unknown environment {env!r}: use 'sim' (compared with thesis Table "
                         f"5.2) or 'hardware' (Table 6.2)")


def _check_pid(names: Mapping[str, object], what: str) -> None:
    if "pid" not in names:
        raise InputError(f"the {what} have no 'pid' scenario (got {sorted(names)}): the "
                         f"improvement ratios are PID alone / scenario, so include the PID-alone "
                         f"run under the name 'pid'")


def _ratios(norms: Mapping[str, float], pid: Mapping[str, float]) -> dict[str, float | None]:
    """The ratio of each norm of one axis (rms_ratio, e2_ratio, einf_ratio, those it has): PID
    alone / scenario, None where the scenario's error is exactly zero (no finite ratio)."""
    return {f"{key}_ratio": pid[key] / norms[key] if norms[key] > 0 else None
            for key in NORMS if key in norms}


def _pid_first(names: Mapping[str, object]) -> list[str]:
    return ["pid", *(name for name in names if name != "pid")]


def own_fields(e2: float, floor: float) -> dict[str, Any]:
    """An axis's own share of `e2` over the noise `floor` (OWN) and whether it is at the floor."""
    return {OWN: own_share(e2, floor), AT_FLOOR: e2 <= floor}


def summarize(metrics: dict[str, dict[str, Any]],
              noise_floor: Mapping[str, float] | None = None) -> dict[str, dict[str, Any]]:
    """Per scenario and axis: rms, e2, einf and their improvement ratios rms_ratio (equal to
    e2_ratio on one reference), e2_ratio, einf_ratio (PID alone / scenario, so the PID's are
    1.0 and higher is better), PID alone first.

    With a LIMIT scenario (iterative learning control's force), every scenario's axis also
    has e2_per_limit: its e2 as a multiple of the limit's (None where the limit's is zero).
    With a `noise_floor` (e2 per axis, learning.ilc.noise_floor), every axis also has own_e2,
    its own share of e2 over the floor (0.0 at or below it), and at_floor.

    `metrics` maps a scenario name to a cosim.metrics.tracking_metrics dict
    {"x": {"e2", "einf", "rms"}, "y": {...}}; it must hold "pid", the base of every ratio.
    """
    _check_pid(metrics, "metrics")
    summary: dict[str, dict[str, Any]] = {}
    for name in _pid_first(metrics):
        summary[name] = {}
        for axis in AXES:
            norms = {key: float(metrics[name][axis][key]) for key in NORMS}
            summary[name][axis] = {**norms, **_ratios(norms, metrics["pid"][axis])}
            if LIMIT in metrics:
                limit = float(metrics[LIMIT][axis]["e2"])
                summary[name][axis][PER_LIMIT] = norms["e2"] / limit if limit > 0 else None
            if noise_floor:
                summary[name][axis].update(own_fields(norms["e2"], float(noise_floor[axis])))
    return summary


def _number(value: float) -> str:
    """A scaled table value: at least three decimals and at least three significant digits."""
    if value == 0:
        return "0.000"
    return f"{value:.{max(3, 2 - math.floor(math.log10(abs(value))))}f}"


def _cell(norms: Mapping[str, float | None], norm: str, scale: float, with_ratio: bool) -> str:
    """One table entry: the value in the table's scale, with its improvement ratio ("–" for
    a norm the column does not have: the thesis gives no e2)."""
    value = norms.get(norm)
    if value is None:
        return "–"
    text = _number(value / scale)
    if not with_ratio:
        return text
    return f"{text} ({_times(norms[f'{norm}_ratio'])})"


def _times(ratio: float | None) -> str:
    """An improvement ratio: "50x", "4.1x"; "n/a" where there is none (a zero error)."""
    if ratio is None:
        return "n/a"
    return f"{ratio:.0f}x" if ratio >= 10 else f"{ratio:.2g}x"


def _multiple(value: float | None) -> str:
    """A multiple of the limit's e2: "12x", "1.4x"; "–" where there is none."""
    return "–" if value is None else f"{value:.3g}x"


def markdown_table(summary: dict[str, dict[str, Any]], env: str) -> str:
    """The thesis's table for `env` ("sim" or "hardware") as Markdown: rows ‖E_x‖₂, ‖E_y‖₂
    (the rms, as the thesis's), e2 x, e2 y (flexff's rms/√T), ‖E_x‖∞, ‖E_y‖∞; a column
    per flexff scenario of `summary` (from `summarize`), then the thesis's columns for the
    same environment, values in the thesis's scale and each feedforward's improvement ratio
    in parentheses, so both can be read side by side."""
    _check_env(env)
    exponent, source = _ENVS[env]
    scale = 10.0**exponent
    thesis = THESIS_TABLES[env]
    columns = [(SCENARIO_LABELS.get(name, name), summary[name], name != "pid")
               for name in summary]
    columns += [(f"thesis: {SCENARIO_LABELS[name]}",
                 {axis: {**table[axis], **_ratios(table[axis], thesis["pid"][axis])}
                  for axis in AXES}, name != "pid")
                for name, table in thesis.items()]
    lines = [f"Tracking error on the evaluation reference, flexff env {env!r} next to {source}: "
             f"values x 1e{exponent}, ‖E‖₂ and ‖E‖∞ in m, e2 in m/√s.",
             "",
             f"| error (x 1e{exponent}) | " + " | ".join(label for label, _, _ in columns) + " |",
             "|---" + "|---:" * len(columns) + "|"]
    for norm, axis, row in _ROWS:
        cells = [_cell(table[axis], norm, scale, with_ratio) for _, table, with_ratio in columns]
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    if LIMIT in summary:
        for axis in AXES:
            cells = [_multiple(table[axis].get(PER_LIMIT)) for _, table, _ in columns]
            lines.append(f"| e2 {axis} / ILC limit | " + " | ".join(cells) + " |")
    lines += ["", "Ratios in parentheses: PID alone / scenario on the same reference (higher "
                  "is better; the thesis's from its own PID-alone column)."]
    if LIMIT in summary:
        lines += ["", "ILC limit: the feedforward force that iterative learning control (flexff "
                      "ilc) learned on this one reference; e2 / ILC limit: each scenario's e2 "
                      "as a multiple of the limit's (1x reaches it)."]
    return "\n".join(lines) + "\n"


def floor_note(summary: Mapping[str, Mapping[str, Any]], floor: Mapping[str, float]) -> str:
    """The noise floor under the table (learning.ilc.noise_floor), with the ILC limit's e2
    as a multiple of it where the summary has the limit."""
    text = (f"Noise floor: e2 x, y = {floor['x']:.3g}, {floor['y']:.3g} m/√s, what the encoders' "
            f"noise and quantization add (the ILC force run with and without them). No "
            f"feedforward removes it")
    if LIMIT in summary:
        text += ("; the ILC limit's is " + " / ".join(
            f"{summary[LIMIT][a]['e2'] / floor[a]:.3g}x" for a in AXES) + " of it")
    return text + ".\n"


NO_FLOOR = ("No noise floor under this table: the loop's encoders measure exactly (as the sim "
            "environment's do) or its plant is an FMU, whose noise flexff cannot switch off; e2 "
            "is not split into the floor and the feedforward's own share.\n")


def _own_cell(axis: Mapping[str, Any]) -> str:
    """An axis's own share of e2 in m/√s, or "at the floor"."""
    return "at the floor" if axis[AT_FLOOR] else f"{axis[OWN]:.3g}"


def own_share_table(summary: Mapping[str, Mapping[str, Any]], floor: Mapping[str, float]
                    ) -> str:
    """Per scenario and axis of `summary` (summarized with the noise `floor`): e2, its ratio
    PID alone / scenario, and its own share over the floor, each own-share column headed
    with the floor it was computed against."""
    head = " | ".join(f"e2 {a} [m/√s] | ratio {a} | own share {a} (floor {floor[a]:.3g})"
                      for a in AXES)
    lines = ["Own share of e2 on the evaluation reference: √(e2² − floor²) in m/√s, what each "
             "feedforward leaves beside the noise floor; \"at the floor\" where e2 ≤ floor.",
             "", f"| scenario | {head} |", "|---" + "|---:" * 3 * len(AXES) + "|"]
    for name, axes in summary.items():
        cells = " | ".join(f"{axes[a]['e2']:.3g} | {_times(axes[a]['e2_ratio'])} | "
                           f"{_own_cell(axes[a])}" for a in AXES)
        lines.append(f"| {SCENARIO_LABELS.get(name, name)} | {cells} |")
    return "\n".join(lines) + "\n"


def held_out_table(held_out: Mapping[str, Any]) -> str:
    """The scenarios' e2 ratios PID alone / scenario on the test split's references
    (learning.held_out): their geometric mean and the worst, x / y."""
    lines = [f"On the {len(held_out['references'])} references of the test split (no model "
             f"trained on them), e2 ratio PID alone / scenario, x / y:", "",
             "| scenario | geometric mean | worst |", "|---|---:|---:|"]
    for name, mean in held_out["geometric_mean"].items():
        worst = held_out["worst"][name]
        lines.append(f"| {SCENARIO_LABELS.get(name, name)} | "
                     + " | ".join(" / ".join(f"{d[a]:.3g}" for a in AXES) for d in (mean, worst))
                     + " |")
    return "\n".join(lines) + "\n"


def _check_recordings(recordings: Mapping[str, Recording]) -> None:
    _check_pid(recordings, "recordings")
    for name, rec in recordings.items():
        needed = TRACKING if name == "pid" else TRACKING + FEEDBACK
        missing = [s for s in needed if s not in rec.signals]
        if name != "pid":
            missing += [n for n in (feedforward_name(rec, k) for k in range(len(AXES)))
                        if n not in rec.signals]
        if missing:
            raise InputError(f"recording {name!r} lacks {missing} (it has "
                             f"{sorted(rec.signals)}): record {list(needed)} in its run")
    base = recordings["pid"]
    for name, rec in recordings.items():
        if rec.time.size != base.time.size:
            raise InputError(f"recording {name!r} has {rec.time.size} points, 'pid' has "
                             f"{base.time.size}: run every scenario with the same reference, "
                             f"step and stop time")
        if not math.isclose(rec.step, base.step, rel_tol=1e-9):
            raise InputError(f"recording {name!r} steps {rec.step:g} s, 'pid' {base.step:g} s: "
                             f"run every scenario with the same communication step")


def _colors(scenarios: Iterable[str]) -> dict[str, str]:
    """One colour per scenario, the same in every figure."""
    return {name: f"C{k}" for k, name in enumerate(scenarios)}


def plot_paths(recordings: Mapping[str, Recording], path: Path) -> Path:
    """Reference and every scenario's x-y path (left), and a zoom (right) centred on the
    reference point where the feedforwards (PID alone if there are none) err most, wide enough
    to hold that error three times over: the view that tells the feedforwards apart."""
    ref = recordings["pid"]
    colors = _colors(recordings)
    figure = Figure(figsize=(11, 5.5))
    full, zoom = figure.subplots(1, 2)
    for ax in (full, zoom):
        ax.plot(ref["x_ref"] * MM, ref["y_ref"] * MM, "k--", lw=1, label="reference", zorder=3)
        for name, rec in recordings.items():
            ax.plot(rec["x"] * MM, rec["y"] * MM, color=colors[name], lw=0.9,
                    label=SCENARIO_LABELS.get(name, name))
        ax.set(xlabel="x [mm]", ylabel="y [mm]", aspect="equal")
    focus = [name for name in recordings if name != "pid"] or ["pid"]
    miss = np.max([np.hypot(recordings[n]["x_ref"] - recordings[n]["x"],
                            recordings[n]["y_ref"] - recordings[n]["y"]) for n in focus],
                  axis=0) * MM
    worst = int(np.argmax(miss))
    extent = max(np.ptp(ref["x_ref"]), np.ptp(ref["y_ref"])) * MM
    half = max(3.0 * miss[worst], 0.02 * extent, 1e-6)
    cx, cy = ref["x_ref"][worst] * MM, ref["y_ref"][worst] * MM
    which = "PID-alone" if focus == ["pid"] else "feedforward"
    zoom.set(xlim=(cx - half, cx + half), ylim=(cy - half, cy + half),
             title=f"zoom at t = {ref.time[worst]:.3f} s (largest {which} error)")
    full.add_patch(Rectangle((cx - half, cy - half), 2 * half, 2 * half, fill=False, lw=1,
                             edgecolor="0.3"))
    full.set_title("x-y path")
    full.legend(loc="best", fontsize="small")
    return save_figure(figure, path)


def plot_errors(recordings: Mapping[str, Recording], path: Path) -> Path:
    """The manipulator's tracking error per axis over time, one line per scenario
    (plot_tracking_errors)."""
    return plot_tracking_errors(
        {name: rec.time for name, rec in recordings.items()},
        {axis: {name: (rec[f"{axis}_ref"] - rec[axis]) * MM for name, rec in recordings.items()}
         for axis in AXES}, dict.fromkeys(AXES, "mm"), path, SCENARIO_LABELS)


def plot_tracking_errors(times: Mapping[str, np.ndarray],
                         errors: Mapping[str, Mapping[str, np.ndarray]],
                         units: Mapping[str, str], path: Path,
                         labels: Mapping[str, str] | None = None) -> Path:
    """Tracking error per axis (`errors`: axis -> scenario -> samples at `times[scenario]`, in
    `units[axis]`) over time, one line per scenario. The scale is symmetric log (linear up to the
    power of ten at or above the smallest scenario's peak error, logarithmic beyond) so a
    feedforward that cuts the error fifty-fold is still readable next to PID alone; lines with
    smaller errors are drawn on top."""
    colors = _colors(times)
    labels = labels or {}
    figure = Figure(figsize=(9, 1.2 + 2.4 * len(errors)))
    axes = figure.subplots(len(errors), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (axis, by_scenario) in zip(axes, errors.items()):
        peaks = {name: float(np.max(np.abs(e))) for name, e in by_scenario.items()}
        for name, error in by_scenario.items():
            ax.plot(times[name], error, color=colors[name], lw=0.8, zorder=-peaks[name],
                    label=labels.get(name, name))
        smallest, largest = min(peaks.values()), max(peaks.values())
        if smallest > 0:
            ax.set_yscale("symlog", linthresh=10.0 ** math.ceil(math.log10(smallest)))
        if largest > 0:
            ax.set_ylim(-1.1 * largest, 1.1 * largest)
        ax.set(ylabel=f"e_{axis} [{units[axis]}]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    axes[0].set_title("tracking error (reference - true position)")
    axes[-1].set_xlabel("time [s]")
    return save_figure(figure, path)


def plot_force_split(recordings: Mapping[str, Recording], path: Path) -> Path:
    """Feedback, feedforward and total force per axis, a row of panels per scenario."""
    figure = Figure(figsize=(11, 2.6 * len(recordings) + 0.6))
    axes = figure.subplots(len(recordings), 2, sharex=True, squeeze=False)
    for row, (name, rec) in zip(axes, recordings.items()):
        for k, (ax, axis) in enumerate(zip(row, AXES)):
            fb, ff = rec[f"F{axis}_fb"], feedforward_of(rec, k)
            ax.plot(rec.time, fb + ff, "k", lw=0.6, label="total")
            ax.plot(rec.time, ff, "C1--", lw=1.0, label="feedforward")
            ax.plot(rec.time, fb, "C0", lw=0.6, label="feedback")
            ax.set(ylabel=f"F_{axis} [N]", title=f"{SCENARIO_LABELS.get(name, name)}: {axis}")
            ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="upper right", ncol=3, fontsize="small")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    return save_figure(figure, path)


TRAINING_KEYS = ("seconds", "epochs", "best_epoch", "parameters", "test_mse", "val_mse",
                 "rigid_body_test_mse", "model_rate_hz", "threads", "members")


def force_gaps(recordings: Mapping[str, Recording]) -> dict[str, dict[str, Any]]:
    """Per feedforward scenario and axis, what its force misses against the LIMIT
    scenario's (learning.force_gap); empty without a LIMIT."""
    if LIMIT not in recordings:
        return {}
    ideal = recordings[LIMIT]
    return {name: {axis: force_gap(feedforward_of(rec, k), feedforward_of(ideal, k), rec.step)
                   for k, axis in enumerate(AXES)}
            for name, rec in recordings.items() if name not in ("pid", LIMIT)}


def force_gap_table(gaps: Mapping[str, Mapping[str, Any]]) -> str:
    """force_gaps as Markdown: a row per scenario and axis."""
    lines = ["Each feedforward's force against the ILC limit's (the best for this reference): "
             "the difference's rms, its power per band, and the shift of the feedforward "
             "that matches best (a shift that helps means a phase error, such as a missing "
             "damping).", "",
             "| scenario | axis | rms [mN] | " + " | ".join(band_names()) +
             " | best shift [ms] | rms there [mN] |",
             "|---|---|---:|" + "---:|" * len(band_names()) + "---:|---:|"]
    for name, axes in gaps.items():
        for axis, gap in axes.items():
            shares = " | ".join(f"{100 * share:.0f} %" for share in gap["band_share"].values())
            lines.append(f"| {SCENARIO_LABELS.get(name, name)} | {axis} | "
                         f"{1e3 * gap['rms_n']:.3g} | {shares} | "
                         f"{1e3 * gap['best_shift_s']:+.0f} | "
                         f"{1e3 * gap['rms_at_best_shift_n']:.3g} |")
    return "\n".join(lines) + "\n"


def training_table(training: Mapping[str, Mapping[str, Any]]) -> str:
    """The cost and fit of each trained model as Markdown: wall time of its training, epochs
    run and the one kept (lowest validation loss), parameters and test MSE (an ensemble's:
    its members' summed time and parameters, mean test MSE)."""
    lines = ["| model | training [s] | epochs (kept) | parameters | test MSE |",
             "|---|---:|---:|---:|---:|"]
    for name, m in training.items():
        label = SCENARIO_LABELS.get(name, name)
        if m.get("members"):
            label += f" ({m['members']} seeds)"
        lines.append(f"| {label} | {m['seconds']:.0f} | "
                     f"{m['epochs']} ({m['best_epoch']}) | {m['parameters']} | "
                     f"{m['test_mse']:.3g} |")
    return "\n".join(lines) + "\n"


def write_report(recordings: dict[str, Recording], env: str, out: str | Path,
                 training: Mapping[str, Mapping[str, Any]] | None = None,
                 noise_floor: Mapping[str, float] | None = None,
                 held_out: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Write summary.json, table.md, paths.png, errors.png and forces.png into `out`; return
    the summary.json content. `training` (model -> learning.train metrics) adds what each
    model's training cost and reached, in both files; `noise_floor` (e2 per axis that the
    encoders add, learning.ilc.noise_floor) adds the floor under every feedforward's e2 and
    each scenario's own share of e2 over it (own_share_table; without one, NO_FLOOR says so);
    `held_out` (learning.held_out.run_held_out) each scenario's ratios on the references of
    the test split. With a LIMIT scenario, each feedforward's force is compared with its
    force (force_gaps).

    `recordings` maps a scenario name ("pid" required; see SCENARIO_LABELS) to the Recording
    of its run on the thesis's evaluation reference, in display order: x_ref, y_ref, x, y for
    every scenario, and Fx_fb, Fy_fb, Fx_ff, Fy_ff for every one but "pid", which is left out
    of forces.png (no forces.png when "pid" is the only scenario). Every run must have the
    same step and length. Everything is checked before a file is written.
    """
    _check_env(env)
    _check_recordings(recordings)
    ordered = {name: recordings[name] for name in _pid_first(recordings)}
    summary = summarize({name: tracking_metrics(rec, named_axes(AXES))
                         for name, rec in ordered.items()},
                        noise_floor)
    content = {"env": env, "scenarios": summary, "thesis": copy.deepcopy(THESIS_TABLES[env]),
               "units": dict(UNITS)}
    table = markdown_table(summary, env)
    if noise_floor:
        content["noise_floor"] = dict(noise_floor)
        table += "\n" + floor_note(summary, noise_floor) + "\n" + own_share_table(
            summary, noise_floor)
    else:
        table += "\n" + NO_FLOOR
    if gaps := force_gaps(ordered):
        content["force_gap"] = gaps
        table += "\n" + force_gap_table(gaps)
    if held_out:
        content["held_out"] = dict(held_out)
        table += "\n" + held_out_table(held_out)
    if training:
        content["training"] = {name: {key: m.get(key) for key in TRAINING_KEYS}
                               for name, m in training.items()}
        table += "\nTraining (test MSE in scaled label units):\n\n" + training_table(training)
    out = Path(out)
    atomic_write(out / "summary.json",
                 lambda tmp: tmp.write_text(json.dumps(content, indent=2) + "\n", "utf-8"))
    atomic_write(out / "table.md",
                 lambda tmp: tmp.write_text(table, "utf-8"))
    plot_paths(ordered, out / "paths.png")
    plot_errors(ordered, out / "errors.png")
    feedforward = {name: rec for name, rec in ordered.items() if name != "pid"}
    if feedforward:
        plot_force_split(feedforward, out / "forces.png")
    return content


def ratio_table(summary: Mapping[str, Any], labels: Mapping[str, str] | None = None,
                number: Callable[[float], str] = lambda value: f"{value:.3g}",
                corner: str = "axis") -> str:
    """A machine evaluation's e2 ratios PID alone / scenario per axis as a Markdown table
    (scenarios headed by `labels`, numbers written by `number`); where the loop's noise floor
    is known, a row per axis of each scenario's e2 over it."""
    scenarios = list(summary["scenarios"])
    lines = [f"| {corner} | " + " | ".join((labels or {}).get(s, s) for s in scenarios) + " |",
             "|---|" + "---:|" * len(scenarios)]
    for axis in summary["axes"]:
        lines.append(f"| {axis} | " + " | ".join(
            number(summary["scenarios"][s][axis]["e2_ratio"]) for s in scenarios) + " |")
    for axis, floor in summary.get("noise_floor", {}).items():
        lines.append(f"| {axis}: e2 / noise floor ({number(floor)}) | " + " | ".join(
            number(summary["scenarios"][s][axis]["e2"] / floor) for s in scenarios) + " |")
    return "\n".join(lines) + "\n"
