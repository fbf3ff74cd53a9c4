"""ONNX export of a training run: SI signals in, forces in newtons out (a current-level run:
motor currents in amperes), state explicit.

One graph serves the sequence form (the whole input, state at zero) and the single-step form
(one row per call, each fed the previous call's state outputs). The model runs at its own
rate (`sample_rate_hz`); a faster runner extrapolates between calls. The pgnn is exported as
its residual over the identified rigid-body feedforward. The metadata is the model card
(learning.model_card); a run without a machine description outputs the signals of its label
level that the implicit machine names (learning.implicit_machine). The graph is checked
against the network and written atomically.

Docs: "File formats", section An exported model (docs/reference/file-formats.md), and "The
learned feedforward FMU" (docs/explanation/learned-feedforward-fmu.md).
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch

from flexff.cosim.recording import atomic_write
from flexff.fmu.errors import InputError, RunError
from flexff.learning.deploy import EnsembleSIModel, SIModel
from flexff.learning.implicit_machine import implicit_machine
from flexff.learning.model_card import ModelCard
from flexff.learning.run_folder import Run, flexff_version, load_run
from flexff.learning.threads import torch_threads

OPSET = 17
TOLERANCE = 1e-5  # largest |onnxruntime - torch| relative to the largest |force|


def export(run: str | Path | Sequence[str | Path], out: str | Path,
           inputs: str = "features") -> Path:
    """Write the ONNX graph of the run folder `run` to the file `out`; return its path.

    Several run folders of one model kind (trained with other seeds) give one graph of their
    mean force (learning.deploy.EnsembleSIModel). `inputs="features"` (default): the graph
    takes the run's features in SI units (63 or 6); `inputs="reference"`: it takes x_ref,
    y_ref, vx_ref, vy_ref, ax_ref, ay_ref and computes the features itself. The export is
    checked: onnxruntime must reproduce PyTorch in both forms to within 1e-5 (relative to the
    largest force), or a RuntimeError is raised.
    """
    folders = [run] if isinstance(run, (str, Path)) else list(run)
    if not folders:
        raise InputError("export needs at least one training run folder")
    with torch_threads():
        return _export([load_run(folder) for folder in folders], Path(out), inputs)


def _export(runs: list[Run], out: Path, inputs: str) -> Path:
    _check_members(runs)
    model = _si_model(runs, inputs)
    stepped = _si_model([replace(r, network=r.network.step_form()) for r in runs], inputs)

    def write(tmp: Path) -> None:
        _write_graph(runs, stepped, inputs, tmp)
        check_export(model, tmp, _probe(runs[0], inputs, 60), name=out)

    return atomic_write(out, write)


def _si_model(runs: list[Run], inputs: str) -> SIModel | EnsembleSIModel:
    # a machine's skip, and that on force inputs, runs beside the graph at the loop's rate: at
    # the model's 25 Hz, sampled and extrapolated, the hardware stand-in's networks with force
    # inputs on ILC labels left 0.56 / 0.70 um/sqrt(s) of e2 of their own, at 1 kHz 0.26 / 0.63
    members = [SIModel(r, inputs, prior=False, skip_outside=r.machine is not None or (
        r.force_input is not None and inputs == "features")) for r in runs]
    return (members[0] if len(members) == 1 else EnsembleSIModel(members)).eval()


def _check_members(runs: list[Run]) -> None:
    """Ensemble members must run alike: same model kind, features (force inputs included),
    rate and prior."""
    def key(r: Run) -> tuple[str, str, float, str, str, str]:
        return (r.config.model, r.config.features.feature_set, r.model_rate_hz,
                json.dumps([r.prior_parameters, r.force_input], sort_keys=True),
                r.config.features.labels,
                json.dumps([r.info.get(k) for k in ("machine", "machine_features")],
                           sort_keys=True))

    if len({key(r) for r in runs}) > 1:
        raise InputError("the runs of one export must share model kind, feature set, model "
                         "rate, prior and labels (the same training data): "
                         + ", ".join(f"{r.path} {key(r)}" for r in runs))


def _write_graph(runs: list[Run], model: SIModel | EnsembleSIModel, inputs: str,
                 path: Path) -> None:
    """The checked graph with its metadata, to `path`."""
    loaded = runs[0]
    state = model.initial_state()
    state_names = model.state_names()
    example = torch.as_tensor(_probe(loaded, inputs, 8), dtype=torch.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            model, (example, *state), str(path), dynamo=False, opset_version=OPSET,
            input_names=["inputs", *state_names],
            output_names=[model.labels, *[f"{n}_out" for n in state_names]],
            dynamic_axes={"inputs": {0: "time"}, model.labels: {0: "time"}})
    graph = onnx.load(str(path))
    machine = loaded.machine
    if machine is None:
        signals = implicit_machine().outputs[model.labels]
        outputs = [v.name for v in signals], [v.unit for v in signals]
    else:
        outputs = [f"{a.name}_ff" for a in machine.axes], [a.effort_unit for a in machine.axes]
    low = np.min([r.feature_scaler.low for r in runs], axis=0)
    high = np.max([r.feature_scaler.high for r in runs], axis=0)
    card = ModelCard(
        model_kind=loaded.config.model, preset=loaded.config.preset,
        ensemble_members=len(runs), feature_set=loaded.config.features.feature_set,
        input_kind=inputs,
        prior=("none" if not model.residual else "rigid-body" if machine is None else "linear"),
        prior_parameters=model.prior_parameters, force_input=model.force_input,
        input_signals=model.input_names,
        input_units=model.input_units,
        output_signals=outputs[0], output_units=outputs[1],
        feature_range={"signals": loaded.feature_names, "low": low.tolist(),
                       "high": high.tolist()},
        sample_rate_hz=float(loaded.model_rate_hz),
        state=[{"input": n, "output": f"{n}_out", "shape": list(s.shape), "initial": "zeros"}
               for n, s in zip(state_names, state)],
        history_samples=max(r.network.history for r in runs), flexff_version=flexff_version(),
        machine=loaded.info.get("machine"), machine_features=loaded.info.get("machine_features"),
        machine_prior=loaded.info.get("machine_prior"),
        linear_inputs=None if model.linear_map is None else {
            "weights": model.linear_map[0].tolist(), "bias": model.linear_map[1].tolist()})
    onnx.helper.set_model_props(graph, card.metadata())
    onnx.checker.check_model(graph)
    onnx.save(graph, str(path))


def session(path: str | Path) -> ort.InferenceSession:
    """An onnxruntime CPU session with one thread: the graphs are small, and spare threads
    waiting for busy cores slow every call down (see learning.train.cpu_threads)."""
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def run_sequence(session: ort.InferenceSession, inputs: np.ndarray) -> np.ndarray:
    """Forces (T, 2) (or currents (T, 3)) for a whole sequence, from the zero state."""
    feed = {"inputs": inputs.astype(np.float64), **_zero_state(session)}
    forces: np.ndarray = session.run([session.get_outputs()[0].name], feed)[0]
    return forces


PRIME_CALLS = 5000  # a primed state: at most this many calls on the first inputs (fmu/c's)
PRIME_SETTLED = 1e-7  # ... until no state element moves by more than this in a call


def run_steps(session: ort.InferenceSession, inputs: np.ndarray, primed: bool = False
              ) -> np.ndarray:
    """Forces (T, 2) (or currents (T, 3)) computed one sample per call, the state passed
    from call to call; from the zero state, or `primed` as the feedforward FMU starts a
    machine's network: at rest on the first inputs (run on them until its state settles)."""
    state = _zero_state(session)
    names = [o.name for o in session.get_outputs()]

    def call(row: np.ndarray, state: dict[str, np.ndarray]
             ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        result = session.run(names, {"inputs": row[None, :], **state})
        return result[0][0], {n[:-len("_out")]: v for n, v in zip(names[1:], result[1:])}
    rows = inputs.astype(np.float64)
    for _ in range(PRIME_CALLS if primed and len(rows) else 0):
        _, settled = call(rows[0], state)
        moved = max((float(np.abs(settled[n] - state[n]).max()) for n in state), default=0.0)
        state = settled
        if moved <= PRIME_SETTLED:
            break
    forces = []
    for row in rows:
        force, state = call(row, state)
        forces.append(force)
    return np.array(forces)


def check_export(model: SIModel | EnsembleSIModel, path: Path, inputs: np.ndarray,
                 name: Path | None = None) -> float:
    """Largest relative deviation of onnxruntime (both forms) from PyTorch on `inputs`;
    RuntimeError (naming the graph `name`, default `path`) if above TOLERANCE."""
    with torch.no_grad():
        expected = model(torch.as_tensor(inputs, dtype=torch.float64),
                         *model.initial_state())[0].numpy()
    runtime = session(path)
    scale = max(float(np.abs(expected).max()), 1e-12)
    worst = max(float(np.abs(run(runtime, inputs) - expected).max()) / scale
                for run in (run_sequence, run_steps))
    if not worst <= TOLERANCE:
        raise RunError(f"{name or path}: onnxruntime deviates from PyTorch by {worst:.3g} "
                       f"(relative), more than {TOLERANCE:g}; the export is not usable")
    return worst


def _zero_state(session: ort.InferenceSession) -> dict[str, np.ndarray]:
    return {i.name: np.zeros(i.shape, dtype=np.float32)
            for i in session.get_inputs() if i.name != "inputs"}


def _probe(run: Run, inputs: str, length: int) -> np.ndarray:
    """Plausible inputs for tracing and checking: a slow circle (reference) or features
    drifting smoothly across the training range."""
    t = np.linspace(0.0, 1.0, length)[:, None]
    if inputs == "reference":
        w = 2 * np.pi
        r = 0.02
        return np.column_stack([r * np.cos(w * t), r * np.sin(w * t), -r * w * np.sin(w * t),
                                r * w * np.cos(w * t), -r * w * w * np.cos(w * t),
                                -r * w * w * np.sin(w * t)])
    low, high = run.feature_scaler.low, run.feature_scaler.high
    phase = np.linspace(0.0, 2 * np.pi, low.size)[None, :]
    features: np.ndarray = low + (high - low) * (0.5 + 0.4 * np.sin(2 * np.pi * t + phase))
    return features
