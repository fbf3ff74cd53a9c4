"""The card of an exported feedforward model: its ONNX metadata as one checked dataclass.

learning.export writes it (`ModelCard.metadata`), the feedforward FMU builder
(controllers.learned_feedforward), the training-range check and the run configurations read
it (`read_card`): the contract between them is written here once, for every machine. What a
card without a machine description means beyond it (its outputs, their units, its parameters)
is the registered machine's (learning.implicit_machine). In the graph it is a set of
string properties (onnx metadata_props; lists and objects as JSON), so any ONNX reader can see
what the model needs and gives: input and output signals with units, the state tensors, the
sample rate, the prior, the model kind and feature set, the range of every feature in the
training data.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import onnx

from flexff.fmu.errors import InputError
from flexff.fmu.system import Variable
from flexff.learning.implicit_machine import implicit_machine

FORMAT = "flexff-feedforward"
VERSION = 1
INPUT_KINDS = ("features", "reference")
PRIORS = ("none", "rigid-body", "linear")  # linear: a machine's identified model
REQUIRED = ("input_kind", "feature_set", "input_signals", "sample_rate_hz")
# the usage text of the metadata, the implicit machine's (its outputs, inputs and prior) between
USAGE = ("inputs (T, n_inputs) float64 in SI units -> outputs (T, n_outputs) float64, the "
         "output_signals in output_units{}; with linear_inputs, plus weights @ inputs + bias "
         "at every step of the runner; state tensors float32. Whole sequence: T samples, state "
         "inputs zero. Step by step: T = 1 every 1/sample_rate_hz s, state inputs = previous "
         "state outputs (zeros first); extrapolate the outputs from the last two calls when "
         "the host runs faster.")
_JSON = ("input_signals", "input_units", "output_signals", "output_units", "state",
         "prior_parameters", "force_input", "feature_range", "machine", "machine_features",
         "machine_prior", "linear_inputs")
_NAME_LISTS = ("input_signals", "input_units", "output_signals", "output_units")
_NUMBERS = {"sample_rate_hz": float, "history_samples": int, "ensemble_members": int}


@dataclass(frozen=True)
class ModelCard:
    """What an exported feedforward model is and how to run it.

    `output_signals`, `output_units`: by default the first outputs of the implicit machine
    (learning.implicit_machine); `state`: one {"input", "output", "shape", "initial"} per state
    tensor (fmu.onnx_graph reads the pairs); `prior_parameters`: the nominal-model parameters
    the prior replaces (the implicit machine's names, SI values); `force_input`: those of the
    rigid-body model whose force along the reference a black-box network takes as its last
    inputs, None for none; `feature_range`: {"signals", "low", "high"} of the training
    data, None for a model exported without it. Another machine's model carries its
    description (`machine`, cosim.machine's table) and the settings of its features
    (`machine_features`: jerk, direction_widths; learning.feature_spec), and outputs
    each axis's `<axis>_ff`; `linear_inputs` {"weights" (outputs x inputs), "bias"}: a linear
    map of the inputs that the runner adds to the graph's outputs at every one of its own steps
    (a network's linear skip, kept out of the graph so that a model called at its slower rate
    still follows friction steps and cogging at the runner's).
    """

    feature_set: str
    input_kind: str
    input_signals: list[str]
    sample_rate_hz: float
    model_kind: str = "ONNX"
    preset: str = ""
    input_units: list[str] = field(default_factory=list)
    output_signals: list[str] = field(default_factory=lambda: [v.name for v in _default()])
    output_units: list[str] = field(default_factory=lambda: [v.unit for v in _default()])
    state: list[dict[str, Any]] = field(default_factory=list)
    history_samples: int = 0
    prior: str = "none"
    prior_parameters: dict[str, float] = field(default_factory=dict)
    force_input: dict[str, float] | None = None
    feature_range: dict[str, Any] | None = None
    ensemble_members: int = 1
    flexff_version: str = "unknown"
    machine: dict[str, Any] | None = None
    machine_features: dict[str, Any] | None = None
    machine_prior: dict[str, Any] | None = None  # the identified linear model (prior "linear")
    linear_inputs: dict[str, Any] | None = None  # added to the outputs at every runner step

    def metadata(self) -> dict[str, str]:
        """The card as onnx metadata_props (strings; lists and objects as JSON)."""
        props = {"format": FORMAT, "format_version": str(VERSION),
                 "usage": USAGE.format(implicit_machine().usage)}
        for key, value in self.__dict__.items():
            if value is None:
                continue
            props[key] = json.dumps(value) if key in _JSON else str(value)
        return props

    @classmethod
    def from_metadata(cls, props: Mapping[str, str], where: str | Path) -> ModelCard:
        """The card of the metadata `props` of the graph `where`; InputError (what is wrong,
        what to do) if they are not those of a flexff feedforward model."""
        if props.get("format") != FORMAT:
            raise InputError(f"{where} is not a flexff feedforward model (metadata format "
                             f"{props.get('format')!r}, expected {FORMAT!r}): export a trained "
                             f"run with `flexff export RUN -o MODEL.onnx`")
        missing = [k for k in REQUIRED if k not in props]
        if missing:
            raise InputError(f"{where}: metadata lacks {', '.join(missing)}; export it again "
                             f"with `flexff export`")
        known = cls.__dataclass_fields__
        values: dict[str, Any] = {}
        for key, text in props.items():
            if key not in known:
                continue
            try:
                values[key] = (json.loads(text) if key in _JSON
                               else _NUMBERS[key](text) if key in _NUMBERS else text)
            except (ValueError, TypeError) as error:
                raise InputError(f"{where}: metadata {key} = {text!r} is not valid ({error}); "
                                 f"export the model again with `flexff export`") from None
            if key in _NAME_LISTS and not (isinstance(values[key], list) and all(
                    isinstance(name, str) for name in values[key])):
                raise InputError(f"{where}: metadata {key} = {text!r} is not a list of names; "
                                 f"export the model again with `flexff export`")
        card = cls(**values)
        card._check(where)
        return card

    @property
    def labels(self) -> str:
        """What the model outputs: the implicit machine's label level of its outputs (the
        manipulator's "forces" or "currents"); a described machine's model "efforts" (its
        axes' <axis>_ff)."""
        if self.machine is not None:
            return "efforts"
        level = implicit_machine().output_level(self.output_signals)
        assert level is not None  # the card's check
        return level

    def _check(self, where: str | Path) -> None:
        if self.machine is not None:
            self._check_machine(where)
            return
        implicit = implicit_machine()
        known = {k: [v.name for v in outputs] for k, outputs in implicit.outputs.items()}
        if implicit.output_level(self.output_signals) is None:
            raise InputError(f"{where}: output signals {self.output_signals} are neither "
                             + " nor ".join(f"the {k} {v}" for k, v in known.items())
                             + "; export the model again with `flexff export`")
        if self.input_kind not in INPUT_KINDS:
            raise InputError(f"{where}: unknown input kind {self.input_kind!r} (known: "
                             f"{', '.join(INPUT_KINDS)})")
        if self.prior not in PRIORS:
            raise InputError(f"{where}: unknown prior {self.prior!r} (known: {', '.join(PRIORS)})")
        for key in ("prior_parameters", "force_input"):
            parameters = getattr(self, key)
            try:
                implicit.check_parameters(parameters or {})  # names and values
            except (TypeError, ValueError) as error:
                raise InputError(f"{where}: metadata {key} {json.dumps(parameters)} are not "
                                 f"nominal-model parameters ({error}); export the model again "
                                 f"with `flexff export`") from None
        if not _linear_map_fits(self.linear_inputs, len(self.output_signals),
                                len(self.input_signals)):
            raise InputError(f"{where}: metadata linear_inputs is not a linear map of the "
                             f"{len(self.input_signals)} inputs to the "
                             f"{len(self.output_signals)} outputs; export the model again with "
                             f"`flexff export`")


    def _check_machine(self, where: str | Path) -> None:
        """Another machine's model: its outputs are its axes' feedforwards, its features
        computed by the FMU from the reference, no manipulator prior."""
        try:
            axes = [a["name"] for a in self.machine["axis"]]  # type: ignore[index]
        except (KeyError, TypeError):
            raise InputError(f"{where}: metadata machine is not a machine description; export "
                             f"the model again with `flexff export`") from None
        if self.output_signals != [f"{a}_ff" for a in axes]:
            raise InputError(f"{where}: output signals {self.output_signals} are not the "
                             f"feedforwards of the machine's axes {axes}; export it again")
        if self.input_kind != "features" or not isinstance(self.machine_features, dict) \
                or self.prior not in ("none", "linear") \
                or (self.prior == "linear") != isinstance(self.machine_prior, dict) \
                or not _linear_map_fits(self.linear_inputs, len(axes),
                                        len(self.input_signals)):
            raise InputError(f"{where}: a machine's model takes its features, carries their "
                             f"settings (machine_features) and, with the prior 'linear', its "
                             f"identified model (machine_prior), and any linear map of its "
                             f"inputs (linear_inputs) of its sizes; export it again with "
                             f"`flexff export`")


def _default() -> tuple[Variable, ...]:
    """The outputs of a card that names none: the implicit machine's first."""
    return next(iter(implicit_machine().outputs.values()))


def _linear_map_fits(linear: Any, n_out: int, n_in: int) -> bool:
    """Whether `linear` is None or {"weights": n_out x n_in numbers, "bias": n_out numbers}."""
    if linear is None:
        return True
    try:
        weights = np.asarray(linear["weights"], dtype=float)
        bias = np.asarray(linear["bias"], dtype=float)
    except (KeyError, TypeError, ValueError):
        return False
    return weights.shape == (n_out, n_in) and bias.shape == (n_out,) \
        and bool(np.all(np.isfinite(weights)) and np.all(np.isfinite(bias)))


def read_card(model: str | Path) -> ModelCard:
    """The card of an exported feedforward model; InputError (what to do) if the file is not
    one."""
    path = Path(model)
    if not path.is_file():
        raise InputError(f"ONNX model {path} does not exist")
    try:
        props = {p.key: p.value for p in onnx.load(str(path), load_external_data=False)
                 .metadata_props}
    except Exception as exc:  # onnx raises DecodeError and others for a broken file
        raise InputError(f"{path} is not a readable ONNX model: {exc}") from exc
    return ModelCard.from_metadata(props, path)
