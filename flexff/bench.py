"""`flexff bench`: speed figures measured in one run, as JSON (ratios where they matter)."""

from __future__ import annotations

import os
import platform
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import onnx

from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.cosim.config import parse_config
from flexff.cosim.engine import idle_timing
from flexff.cosim.floor import run_c_loop
from flexff.cosim.libcosim import run_libcosim, time_libcosim_engine
from flexff.cosim.master import Master, ResolvedFmu
from flexff.cosim.metrics import named_axes, tracking_metrics
from flexff.cosim.realtime import realtime_process
from flexff.cosim.recording import Recording
from flexff.cosim.run import run_config, simulate
from flexff.cosim.scenario import Scenario, reference_signals, resolve
from flexff.cosim.schema import RunConfig
from flexff.cosim.timing import PERCENTILES, US, Pacing, StepTiming
from flexff.fmu.build import build_fmu
from flexff.fmu.defaults import DEFAULT_STEP
from flexff.fmu.errors import InputError
from flexff.fmu.network_runtime import RUNTIMES
from flexff.fmu.onnx_fmu import onnx_system
from flexff.fmu_bench import bench_fmu
from flexff.plant.signals import AXES
from flexff.plant.system import plant_system

CLOSED_LOOP_REFERENCE = "thesis-eval"  # the thesis's evaluation reference, 15 s at 1 ms
REALTIME_MODELS = ("tcn", "lstm")  # the thesis ran these on Simulink Real-Time


def closed_loop_scenario(folder: Path, feedforward: dict[str, str] | None = None) -> Scenario:
    """PID + nominal plant (and `feedforward`, a [feedforward] table) on the thesis's
    evaluation reference, resolved with its FMUs in `folder`."""
    config = parse_config({"reference": {"kind": CLOSED_LOOP_REFERENCE},
                           "feedforward": feedforward or {"kind": "none"}}, name="bench")
    return resolve(config, folder)


def _best_wall(scenario: Scenario, repeats: int) -> float:
    """The fastest of `repeats` runs of the scenario through cosim.master (loop time)."""
    walls = []
    for _ in range(repeats):  # a Master runs once
        with scenario.master() as master:
            walls.append(master.run(scenario.sources, scenario.steps, progress=False).wall_s)
    return min(walls)


def closed_loop_benchmark(folder: Path, repeats: int = 3) -> dict[str, Any]:
    """Real-time factor of PID + nominal plant on the thesis's evaluation reference through
    cosim.master, libcosim's master (fed and read through libcosimpy every step, and its engine
    alone: all steps in one call) and the C floor (cosim.floor: the engine's loop run from C,
    no Python between chunks), best of `repeats` runs each (libcosim steps its FMUs on a thread
    pool, whose hand-offs make its times vary from run to run). Cross-checks: the floor must
    record the master's numbers bit for bit; libcosim's Jacobi timing (cosim.libcosim) moves
    the end effector by up to `libcosim_max_position_gap_m`."""
    scenario = closed_loop_scenario(folder)
    steps, step, sources = scenario.steps, scenario.step, scenario.sources
    ours: list[Recording] = []
    for _ in range(repeats):
        with scenario.master() as master:
            if not ours:
                c_record, c_us = run_c_loop(master, sources, steps, repeats)
            ours.append(master.run(sources, steps, progress=False))
    best = min(r.wall_s for r in ours)
    theirs = [run_libcosim(scenario.fmus, sources, step, steps, ["x", "y"])
              for _ in range(repeats)]
    engine_s = min(time_libcosim_engine(scenario.fmus, sources, step, steps)
                   for _ in range(repeats))
    master_us, engine_us = 1e6 * best / steps, 1e6 * engine_s / steps
    libcosim_us = 1e6 * min(r.wall_s for r in theirs) / steps
    us = {"master": master_us, "libcosim": libcosim_us, "libcosim_engine": engine_us, "c": c_us}
    gap = max(float(np.abs(theirs[0][n] - ours[0][n][1:]).max()) for n in ("x", "y"))
    return {
        "reference": CLOSED_LOOP_REFERENCE, "stop_s": scenario.config.stop, "steps": steps,
        "us_per_step": us,
        "real_time_factor": {k: step / (v * 1e-6) for k, v in us.items()},
        "ratio_master_over_c": master_us / c_us,
        "ratio_libcosim_over_master": libcosim_us / master_us,
        "ratio_libcosim_engine_over_master": engine_us / master_us,
        "c_equals_master": all(np.array_equal(c_record[n], ours[0][n]) for n in ours[0].signals),
        "libcosim_max_position_gap_m": gap,
    }


def untrained_models(folder: Path) -> dict[str, Path]:
    """ONNX exports of every model kind at the fast preset's sizes, trained for one epoch on a
    small synthetic dataset: what a step costs does not depend on the weights."""
    from flexff.learning.evaluate import MODELS
    from flexff.learning.export import export
    from flexff.learning.synthetic import synthetic_dataset
    from flexff.learning.train import train

    data = synthetic_dataset(folder / "data", n_train=3, n_test=1, duration=6.0, rate_hz=100.0,
                             seed=1)
    models = {}
    for kind in MODELS:
        train(kind, "fast", data, folder / "runs" / kind, progress=False, epochs=1)
        models[kind] = export(folder / "runs" / kind, folder / f"{kind}.onnx")
    return models


def learned_feedforward_benchmark(folder: Path, models: dict[str, Path],
                                  repeats: int = 2) -> dict[str, Any]:
    """Real-time factor of the closed loop (feedforward FMU + PID + nominal plant, thesis
    evaluation reference, through cosim.master) with each learned model, step by step and
    precomputed, best of `repeats`; its cost over the loop without feedforward."""
    loop = closed_loop_scenario(folder)
    steps, stop = loop.steps, loop.config.stop
    base = _best_wall(loop, repeats)
    results: dict[str, Any] = {"reference": CLOSED_LOOP_REFERENCE, "steps": steps,
                               "without_feedforward_us_per_step": 1e6 * base / steps}
    for kind, model in models.items():
        for mode in ("step", "precomputed"):
            scenario = closed_loop_scenario(folder, {"kind": "learned", "model": str(model),
                                                     "mode": mode})
            wall = _best_wall(scenario, repeats)
            results[f"{kind}_{mode}"] = {
                "us_per_step": 1e6 * wall / steps,
                "real_time_factor": stop / wall,
                "ratio_over_without_feedforward": wall / base}
    return results


def network_call_benchmark(folder: Path, models: dict[str, Path],
                           runtimes: tuple[str, ...] = RUNTIMES,
                           repeats: int = 3) -> dict[str, Any]:
    """The network's time per call in the learned feedforward FMU (step mode, 1 ms) with each
    model, its network computed by each of `runtimes` (generated C, onnxruntime): the FMU
    alone, unpaced, fed the thesis's evaluation reference (15 s: a call at initialization,
    then one per model period), its call times read from the FMU's own histogram
    (`flexff_network_times`: p50 and p99 are the upper edges of its bins, 20 per decade); of
    `repeats` runs, the runtimes alternated, the one with the lowest p99 (a shared machine's
    other work lands in a run's tail); each FMU's size zipped; per model, C over onnxruntime
    of p50 and p99."""
    config = parse_config({"reference": {"kind": CLOSED_LOOP_REFERENCE}}, name="bench")
    sources, steps, step = reference_signals(config), config.steps, config.step
    results: dict[str, Any] = {"reference": CLOSED_LOOP_REFERENCE, "steps": steps,
                               "mode": "step", "repeats": repeats, "models": {}}
    for kind, model in models.items():
        fmus = {runtime: build_fmu(learned_feedforward_system(model, step, runtime=runtime),
                                   folder / f"network-{kind}-{runtime}.fmu")
                for runtime in runtimes}
        runs: dict[str, list[dict[str, float]]] = {runtime: [] for runtime in runtimes}
        for _ in range(repeats):
            for runtime, fmu in fmus.items():
                with Master([ResolvedFmu("feedforward", fmu)], list(sources), step) as master:
                    timing = master.run(sources, steps, progress=False).timing
                runs[runtime].append(timing.network_calls["feedforward"])
        figures: dict[str, Any] = {}
        for runtime, fmu in fmus.items():
            times = min(runs[runtime], key=lambda t: (t["p99"], t["p50"]))
            figures[runtime] = {"calls": int(times["calls"]), "p50_us": times["p50"],
                                "p99_us": times["p99"], "max_us": times["max"],
                                "fmu_bytes": fmu.stat().st_size}
        if {"c", "onnxruntime"} <= set(figures):
            figures["ratio_c_over_onnxruntime"] = {
                q: figures["c"][f"{q}_us"] / figures["onnxruntime"][f"{q}_us"]
                for q in ("p50", "p99")}
        results["models"][kind] = figures
    return results


def network_call_table(figures: dict[str, Any]) -> str:
    """network_call_benchmark's figures as text: per model and runtime the time per call p50 /
    p99 [µs] and the FMU's size zipped [MB], and C over onnxruntime."""
    runtimes = [r for r in RUNTIMES if any(r in m for m in figures["models"].values())]
    both = len(runtimes) == 2
    label = {"c": "C", "onnxruntime": "onnxruntime"}
    rows = [["model", *(f"{label[r]} {what}" for r in runtimes
                        for what in ("p50 / p99 [µs]", "FMU [MB]")),
             *(["C / onnxruntime p50 / p99"] if both else [])]]
    for kind, model in figures["models"].items():
        row = [kind]
        for r in runtimes:
            row += [f"{model[r]['p50_us']:.3g} / {model[r]['p99_us']:.3g}",
                    f"{model[r]['fmu_bytes'] / 1e6:.3g}"]
        if both:
            ratio = model["ratio_c_over_onnxruntime"]
            row.append(f"{ratio['p50']:.3g} / {ratio['p99']:.3g}")
        rows.append(row)
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) if i == 0 else cell.rjust(w)
                       for i, (cell, w) in enumerate(zip(row, widths))) for row in rows]
    return "\n".join([f"network time per call ({figures['reference']}, {figures['mode']} mode)",
                      *lines])


HARDWARE_REFERENCE = "thesis-hardware-eval"  # the paced loops' reference, 100 s


def _hardware_loop_config(seconds: float | None, name: str, **tables: dict[str, Any]
                         ) -> RunConfig:
    """The closed loop of the hardware evaluation (hardware plant, PID with notch, the thesis
    hardware reference) for its 100 s or its first `seconds`, with further `tables`."""
    return parse_config({
        "run": {} if seconds is None else {"stop": seconds},
        "reference": {"kind": HARDWARE_REFERENCE},
        "plant": {"variant": "hardware", "seed": 1}, **tables}, name=name)


def _hardware_loop(folder: Path, model: Path, mode: str, seconds: float | None,
                   runtime: str = RUNTIMES[0]) -> Scenario:
    """The hardware loop with the learned feedforward `model` in `mode`, its network computed
    by `runtime`, resolved."""
    return resolve(_hardware_loop_config(
        seconds, f"realtime-{model.stem}-{mode}-{runtime}",
        feedforward={"kind": "learned", "model": str(model), "mode": mode,
                     "runtime": runtime}), folder)


def _e2(recording: Recording) -> dict[str, float]:
    """The thesis's average 2-norm of the tracking error per axis [m/sqrt(s)]."""
    return {axis: m["e2"] for axis, m in tracking_metrics(recording, named_axes(AXES)).items()}


def realtime_benchmark(folder: Path, models: dict[str, Path], seconds: float | None = None,
                       kinds: tuple[str, ...] = REALTIME_MODELS,
                       runtimes: tuple[str, ...] = RUNTIMES) -> dict[str, Any]:
    """The closed loop of the hardware evaluation (hardware plant, PID with notch, thesis
    hardware reference: 100 s, or its first `seconds`) with the TCN and the LSTM feedforward,
    its network in its own task (mode "task") computed by each of `runtimes` (the default, C,
    under the model's name; another as `MODEL_RUNTIME`), paced at 1 kHz: per task (the 1 kHz
    base task, the network's), TET p50 / p99 / max and overruns, each FMU's share; the
    feedforward's share split into the steps that hand a call over to the network's task and
    the others, and the calls handed over, waited for and computed in the base task
    (`feedforward_step`); the tracking (e2) against the single-rate feedforward (mode "step",
    the network inside the 1 kHz step, run unpaced: the same run as paced, bit for bit, and
    its TET for comparison). As floors, the same paced loop without the feedforward
    (`no_feedforward`: the TET the loop's other FMUs and the machine's jitter give), with no
    FMU for as long (`idle`: the lateness and overruns the machine alone causes), a one-node
    graph FMU
    (`one_node_graph`) and a network made deliberately slower than the period in its own task
    at 25 Hz (`slow_network`), each run as --realtime runs (cosim.realtime: SCHED_FIFO and
    locked memory where permitted), pinned to one CPU (`paced_cpu`) as `flexff run --realtime
    --cpu K` runs: the network's task then runs on that core in the base task's idle time."""
    cpu = paced_cpu()
    results: dict[str, Any] = {"reference": HARDWARE_REFERENCE, "cpu": cpu}
    paced_s = 0.0
    for kind in kinds:
        single = simulate(_hardware_loop(folder, models[kind], "step", seconds), progress=False)
        e2_step = _e2(single)
        for runtime in runtimes:
            recording = simulate(_hardware_loop(folder, models[kind], "task", seconds, runtime),
                                 progress=False, pacing=Pacing(rt_factor=1.0), cpu=cpu)
            table = recording.timing.table(recording.wall_s)
            e2_task = _e2(recording)
            results[kind if runtime == RUNTIMES[0] else f"{kind}_{runtime}"] = {
                "runtime": runtime,
                **{key: table[key] for key in (
                    "period_us", "achieved_real_time_factor", "tasks", "tet_us_per_fmu",
                    "tet_over_period_p99", "lateness_us", "overruns",
                    "rate_transition_overruns", "network_call_us", "process")},
                "feedforward_step": feedforward_step(recording.timing),
                "single_rate_unpaced_tet_us": single.timing.table(single.wall_s)["tet_us"],
                "tracking_e2": {"task": e2_task, "single_rate": e2_step,
                                "task_over_single_rate": {a: e2_task[a] / e2_step[a]
                                                          for a in e2_task}}}
            paced_s = recording.timing.tet.size * recording.timing.period
    bare = simulate(resolve(_hardware_loop_config(seconds, "realtime-no-feedforward"), folder),
                    progress=False, pacing=Pacing(rt_factor=1.0), cpu=cpu)
    table = bare.timing.table(bare.wall_s)
    results["no_feedforward"] = {key: table[key] for key in (
        "period_us", "tasks", "tet_us_per_fmu", "lateness_us", "overruns")}
    with realtime_process(cpu):  # every paced loop here runs as --realtime --cpu runs it
        idle = idle_timing(paced_s)
    table = idle.table(idle.tet.size * idle.period)
    results["idle"] = {key: table[key] for key in ("period_us", "steps", "tet_us", "lateness_us",
                                                   "overruns")}
    results["one_node_graph"] = one_node_graph_benchmark(folder, paced_s)
    results["slow_network"] = slow_network_benchmark(folder, paced_s)
    return results


def feedforward_step(timing: StepTiming, fmu: str = "feedforward") -> dict[str, Any]:
    """The share of `fmu` (a network in its own task) in each step's TET [us], split into the
    steps at its call points, which hand a call over to the network's task (and take the last
    one's result), and the others; its p99 over its p50 in all steps; the calls handed over
    (`handovers`: one per call point), those whose hand-over woke the task with a system
    call (`signalled`: where the calls come at a steady rate the clock releases it instead,
    all but the first three), those whose result the base task waited for (not ready when
    due) and those computed in the base task (by the step itself, or by the network's task
    preempting it: never, when the task works as it should)."""
    calls = timing.network_calls[fmu]
    share = timing.fmu_tet[:, timing.names.index(fmu)]
    handover = np.arange(share.size) % int(calls["period_steps"]) == 0
    return {"tet_us": {"handover": _us_stats(share[handover]),
                       "no_handover": _us_stats(share[~handover])},
            "p99_over_p50": float(np.percentile(share, 99) / np.percentile(share, 50)),
            "handovers": int(calls.get("handovers", handover.sum())),
            "signalled": int(calls.get("signalled", 0)),
            "waited_for": int(calls.get("overruns", 0)),
            "computed_in_base_task": int(calls.get("computed_in_step", 0))}


def _us_stats(seconds: np.ndarray) -> dict[str, float]:
    """p50, p99, p99.9 and max of durations in seconds, in microseconds."""
    return {**{name: float(np.percentile(seconds, q)) * US for name, q in PERCENTILES.items()},
            "max": float(seconds.max()) * US}


def realtime_table(figures: dict[str, Any]) -> str:
    """realtime_benchmark's paced loops as text: per loop the 1 kHz task's TET p50 / p99 /
    max and overruns, the feedforward's step p50 / p99 at call points (a hand-over) and
    between them, its p99 over p50, and the calls handed over, signalled, waited for and
    computed in the base task; the loop without feedforward's and the idle loop's TET and
    overruns."""
    rows = [["loop", "TET p50 / p99 / max [µs]", "overruns",
             "ff step, hand-over p50 / p99", "ff step, none p50 / p99", "ff p99/p50",
             "hand-overs / signalled / waited / in base task"]]
    for name, loop in figures.items():
        if not (isinstance(loop, dict) and "feedforward_step" in loop):
            continue
        tet, ff = loop["tasks"]["base"]["tet_us"], loop["feedforward_step"]
        split = ff["tet_us"]
        rows.append([name, f"{tet['p50']:.3g} / {tet['p99']:.3g} / {tet['max']:.3g}",
                     str(loop["overruns"]),
                     f"{split['handover']['p50']:.3g} / {split['handover']['p99']:.3g}",
                     f"{split['no_handover']['p50']:.3g} / {split['no_handover']['p99']:.3g}",
                     f"{ff['p99_over_p50']:.3g}",
                     f"{ff['handovers']} / {ff['signalled']} / {ff['waited_for']} / "
                     f"{ff['computed_in_base_task']}"])
    for name, floor in (("no feedforward", figures.get("no_feedforward")),
                        ("idle", figures["idle"])):
        if floor is None:
            continue
        tet = floor["tasks"]["base"]["tet_us"] if "tasks" in floor else floor["tet_us"]
        rows.append([name, f"{tet['p50']:.3g} / {tet['p99']:.3g} / {tet['max']:.3g}",
                     str(floor["overruns"]), "–", "–", "–", "–"])
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) if i == 0 else cell.rjust(w)
                       for i, (cell, w) in enumerate(zip(row, widths))) for row in rows]
    return "\n".join([f"paced at 1 kHz on CPU {figures['cpu']} ({figures['reference']}), "
                      f"the feedforward's step in µs", *lines])


def paced_cpu() -> int:
    """The CPU the bench's paced loops are pinned to: the last this process may run on (the
    first is where an idle machine's interrupts and housekeeping land most)."""
    return max(os.sched_getaffinity(0))


RECORDING_PAIRS = 2  # runs with the record on, then off, alternated this many times
# the least a run's record can be: no signal beside time, no plot (the metrics still see the
# reference and the true position, which the master then records alone)
LEAST_RECORD = {"signals": [], "plot": False}


def recording_benchmark(folder: Path, seconds: float | None = None,
                        pairs: int = RECORDING_PAIRS) -> dict[str, Any]:
    """What writing the record costs a paced run: the hardware evaluation loop (hardware
    plant, PID with notch, thesis hardware reference: 100 s or its first `seconds`, no
    feedforward) paced at 1 kHz through cosim.run.run_config, as `flexff run --realtime --cpu
    K` runs it (the record written by a thread of its own), with every signal recorded and plotted
    (the default [record], `on`) and with the least record (LEAST_RECORD, `off`), alternated
    `pairs` times: per run the base task's TET p50 / p99 / max, the lateness p99 and the
    overruns; per mode the median over its runs, and on over off of TET p50 and p99."""
    runs: dict[str, list[dict[str, Any]]] = {"on": [], "off": []}
    for i in range(pairs):
        for mode, record in (("on", {}), ("off", LEAST_RECORD)):
            config = _hardware_loop_config(seconds, f"recording-{mode}", record=record)
            table = run_config(config, folder / f"recording-{mode}-{i}", progress=False,
                               pacing=Pacing(rt_factor=1.0), cpu=paced_cpu())["realtime"]
            tet = table["tasks"]["base"]["tet_us"]
            runs[mode].append({"tet_us": {k: tet[k] for k in ("p50", "p99", "max")},
                               "lateness_p99_us": table["lateness_us"]["p99"],
                               "overruns": table["overruns"], "steps": table["steps"]})
    median = {mode: _median_run(done) for mode, done in runs.items()}
    return {"reference": HARDWARE_REFERENCE, "period_us": 1e3, "off_record": LEAST_RECORD,
            "runs": runs, "median": median,
            "ratio_on_over_off": {k: median["on"]["tet_us"][k] / median["off"]["tet_us"][k]
                                  for k in ("p50", "p99")}}


def _median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The median of each figure of recording_benchmark's runs of one mode."""
    return {"tet_us": {k: float(np.median([r["tet_us"][k] for r in runs]))
                       for k in ("p50", "p99", "max")},
            "lateness_p99_us": float(np.median([r["lateness_p99_us"] for r in runs])),
            "overruns": float(np.median([r["overruns"] for r in runs]))}


def slow_network_benchmark(folder: Path, seconds: float, every: int = 40,
                           step: float = DEFAULT_STEP) -> dict[str, Any]:
    """A network slower than the period (slow_graph, about 3 ms a call in onnxruntime) in its
    own task every `every` steps of `step` seconds (25 Hz at 1 kHz), paced alone for `seconds`:
    the base task's TET and overruns (which the network must not cause) and the network
    task's."""
    fmu = build_fmu(onnx_system(slow_graph(folder / "slow.onnx"), step, every, task=True,
                                runtime="onnxruntime"), folder / "slow.fmu")
    table = _paced_alone(ResolvedFmu("slow", fmu), {"inputs[0]": 1.0, "inputs[1]": 2.0},
                         seconds, step)
    return {"every_steps": every, "tasks": table["tasks"], "lateness_us": table["lateness_us"],
            "overruns": table["overruns"],
            "rate_transition_overruns": table["rate_transition_overruns"]}


def one_node_graph_benchmark(folder: Path, seconds: float, every: int = 40,
                             step: float = DEFAULT_STEP) -> dict[str, Any]:
    """The floor of an onnxruntime call in a paced loop: a graph of one Add node as an FMU (its
    network in onnxruntime), called every `every` steps of `step` seconds (the hardware models'
    25 Hz at 1 kHz), paced alone for `seconds`. Its call time is what a network call costs on
    this machine before any arithmetic."""
    graph = onnx.helper.make_graph(
        [onnx.helper.make_node("Add", ["u", "u"], ["y"])], "one_node",
        [onnx.helper.make_tensor_value_info("u", onnx.TensorProto.DOUBLE, [1, 2])],
        [onnx.helper.make_tensor_value_info("y", onnx.TensorProto.DOUBLE, [1, 2])])
    model = onnx.helper.make_model(graph, opset_imports=[onnx.helper.make_opsetid("", 17)],
                                   ir_version=9)  # onnx's default is newer than onnxruntime reads
    onnx.save(model, folder / "one_node.onnx")
    fmu = build_fmu(onnx_system(folder / "one_node.onnx", step, every, runtime="onnxruntime"),
                    folder / "one_node.fmu")
    table = _paced_alone(ResolvedFmu("graph", fmu), {"u[0]": 1.0, "u[1]": 2.0}, seconds, step)
    return {"every_steps": every, "tet_us": table["tet_us"],
            "network_call_us": table["network_call_us"]["graph"]}


def _paced_alone(fmu: ResolvedFmu, inputs: dict[str, float], seconds: float,
                 step: float) -> dict[str, Any]:
    """The realtime table of `fmu` alone, its inputs held constant, paced at `step` for
    `seconds` as `--realtime --cpu K` runs it."""
    with Master([fmu], list(inputs), step) as master, realtime_process(paced_cpu()):
        recording = master.run(inputs, max(1, round(seconds / step)),
                               pacing=Pacing(rt_factor=1.0))
    table: dict[str, Any] = recording.timing.table(recording.wall_s)
    return table


def slow_graph(path: Path, size: int = 256, layers: int = 6) -> Path:
    """A graph made deliberately slow (a network longer than the 1 kHz period): forces = inputs
    (2 columns, exactly, whatever the weights), after `layers` products of a `size` x `size`
    matrix scaled by the inputs' sum, each through tanh (onnxruntime cannot fold them away).
    At 256 and 6, a call takes about 3 ms in onnxruntime on one core of the development
    machine (its matrix-matrix products are blocked and vectorized; as generated C, whose
    kernels are for the matrix-vector products of one row per call, 50 ms)."""
    rng = np.random.default_rng(0)
    weights = onnx.helper.make_tensor("w", onnx.TensorProto.DOUBLE, [size, size],
                                      (rng.standard_normal((size, size)) / size).ravel())
    make = onnx.helper.make_node
    nodes = [make("Constant", [], ["weights"], value=weights),
             make("ReduceSum", ["inputs"], ["scale"], keepdims=1),
             make("Mul", ["weights", "scale"], ["a0"])]
    for i in range(layers):
        nodes += [make("MatMul", [f"a{i}", "weights"], [f"m{i}"]),
                  make("Tanh", [f"m{i}"], [f"a{i + 1}"])]
    nodes += [make("ReduceSum", [f"a{layers}"], ["total"], keepdims=1),
              make("IsNaN", ["total"], ["nan"]),  # 0 for any finite input: forces = inputs
              make("Cast", ["nan"], ["zero"], to=onnx.TensorProto.DOUBLE),
              make("Add", ["inputs", "zero"], ["forces"])]
    graph = onnx.helper.make_graph(
        nodes, "slow",
        [onnx.helper.make_tensor_value_info("inputs", onnx.TensorProto.DOUBLE, [1, 2])],
        [onnx.helper.make_tensor_value_info("forces", onnx.TensorProto.DOUBLE, [1, 2])])
    onnx.save(onnx.helper.make_model(graph, opset_imports=[onnx.helper.make_opsetid("", 17)],
                                     ir_version=9), path)
    return path


def run_benchmarks(steps: int = 20000, repeats: int = 5,
                   models: dict[str, Path] | None = None,
                   realtime_seconds: float | None = None) -> dict[str, Any]:
    """Cost of a 1 ms plant step through fmpy's low-level API and in plain C, per variant, of
    the closed loop through our master, libcosim and C, of the closed loop with each learned
    feedforward FMU (`models`: kind -> .onnx; default: untrained exports) and the time per
    call of each model's network in generated C and in onnxruntime, the paced
    hardware evaluation loop with the TCN and LSTM feedforward (`realtime_seconds` of its
    100 s; default all) with its floors, and that loop without feedforward paced with its
    record written and with the least record (recording_benchmark)."""
    for name, value in (("steps", steps), ("repeats", repeats)):
        if not isinstance(value, int) or value < 1:
            raise InputError(f"bench {name} must be a whole number of at least 1, got {value!r}")
    if realtime_seconds is not None and not realtime_seconds > 0:
        raise InputError(f"bench realtime seconds must be positive, got {realtime_seconds!r} "
                         f"(leave it out for the whole 100 s)")
    results: dict[str, Any] = {"machine": platform.processor() or platform.machine(),
                               "python": platform.python_version(), "plant_step": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for variant in ("nominal", "hardware"):
            path = build_fmu(plant_system(variant), Path(tmp) / f"plant_{variant}.fmu")
            figures = bench_fmu(path, steps=steps, repeats=repeats)
            figures["real_time_factor_fmpy"] = 1e3 / figures["python_us_per_step"]
            results["plant_step"][variant] = figures
        results["closed_loop"] = closed_loop_benchmark(Path(tmp))
        models = models or untrained_models(Path(tmp))
        results["learned_feedforward"] = learned_feedforward_benchmark(Path(tmp), models)
        results["network_call"] = network_call_benchmark(Path(tmp), models)
        results["realtime"] = realtime_benchmark(Path(tmp), models, realtime_seconds)
        results["realtime"]["recording"] = recording_benchmark(Path(tmp), realtime_seconds)
    return results
