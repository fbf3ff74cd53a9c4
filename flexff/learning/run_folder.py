"""A training run on disk: `run.json` (everything needed to rebuild) and `model.pt` (weights).

run.json holds the training configuration, the feature and label names, the model's sample
rate, the min-max scalers fitted on the training data, where the data came from and the sha256
of model.pt; with the weights that is enough to rebuild the network and run it in SI units
(`learning.deploy`).

Nothing a failure can destroy: while training, `checkpoint.pt` (everything needed to go on,
every few epochs) and `best.pt` (the weights of the best epoch so far) are written atomically
beside a finished run's files; a run's own files are written in full to a hidden staging folder
and only then renamed over the old ones (run.json last), and the checkpoints are deleted after.
A damaged folder is refused with a one-line message naming the file (RunFolderError).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from flexff.cosim.machine import Machine, parse_machine
from flexff.cosim.recording import atomic_write
from flexff.fmu.cache import file_sha256
from flexff.fmu.errors import InputError
from flexff.learning.feature_spec import FeatureInputs
from flexff.learning.models import SequenceNetwork, build_network
from flexff.learning.presets import TrainConfig
from flexff.learning.scaling import MinMaxScaler

if TYPE_CHECKING:
    from flexff.learning.features import FeatureConfig

FORMAT = "flexff-run"
VERSION = 1
RUN_FILE = "run.json"
WEIGHTS_FILE = "model.pt"
CHECKPOINT_FILE = "checkpoint.pt"
BEST_FILE = "best.pt"
CHECKPOINT_FORMAT = "flexff-checkpoint"
CHECKPOINT_KEYS = ("settings", "epoch", "epochs", "network", "optimizer", "best", "best_state",
                   "rng", "torch_rng", "cuda_rng", "history")  # learning.train fills them
STAGING = ".staging-"  # prefix of the hidden folder a run's files are written to first


class RunFolderError(InputError):
    """A run folder that cannot be used or written as asked; the message says what to do."""


def flexff_version() -> str:
    """The installed flexff distribution's version ('unknown' when run from a bare checkout)."""
    try:
        return metadata.version("flexff")
    except metadata.PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class RunConfig(TrainConfig):
    """A finished run's training configuration with the feature settings its run.json
    records beside it (TrainConfig.record): the data source's."""

    feature_record: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def read(cls, record: Mapping[str, Any]) -> RunConfig:
        """The configuration of run.json's `config` record."""
        return cls(**vars(TrainConfig.from_record(record)),
                   feature_record=dict(record["features"]))

    @property
    def features(self) -> FeatureConfig:
        """The feature settings as the manipulator's preprocessing (learning.features) reads
        them: a machine's run, which records edge_periods alone, reads the defaults."""
        from flexff.learning.features import FeatureConfig

        return FeatureConfig(**{k: v for k, v in self.feature_record.items()
                                if k != "edge_periods"})


@dataclass(frozen=True)
class Run:
    """A rebuilt training run: configuration, trained network (eval mode, CPU) and scalers."""

    path: Path
    config: RunConfig
    network: SequenceNetwork
    feature_scaler: MinMaxScaler
    label_scaler: MinMaxScaler
    feature_names: list[str]
    model_rate_hz: float
    info: dict[str, Any]

    @property
    def machine(self) -> Machine | None:
        """The description of the machine a run of learning.description_data learned (None: the
        manipulator's run)."""
        table = self.info.get("machine")
        return None if table is None else parse_machine(table, str(self.path / RUN_FILE))

    @property
    def feature_inputs(self) -> FeatureInputs:
        """The feature choices of a machine's run (learning.machine_features)."""
        return FeatureInputs.from_settings(self.info["machine_features"])

    @property
    def prior_parameters(self) -> dict[str, float]:
        """The nominal-model parameters a physics-guided model's prior replaces (its identified
        rigid-body model, learning.identify); empty for other models and runs from before."""
        return dict(self.info.get("prior_parameters", {}))

    @property
    def force_input(self) -> dict[str, float] | None:
        """The parameters of the identified rigid-body model whose force a black-box network
        takes as its last inputs (learning.features.FeatureConfig.force_input); None: none."""
        parameters = self.info.get("force_input")
        return None if parameters is None else dict(parameters)


def save_run(out: Path, config_record: dict[str, Any], network: SequenceNetwork,
             feature_scaler: MinMaxScaler, label_scaler: MinMaxScaler, feature_names: list[str],
             label_names: list[str], model_rate_hz: float, extra: dict[str, Any],
             files: Mapping[str, Callable[[Path], object]]) -> None:
    """Write model.pt, run.json and `files` (name -> writer of that file) into `out`, then
    delete the checkpoints; a finished run's files there change only once all new ones are
    complete. run.json's `config` is `config_record` (learning.presets.TrainConfig.record)."""
    out.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out, prefix=STAGING))
    try:
        torch.save({k: v.detach().cpu() for k, v in network.state_dict().items()},
                   staging / WEIGHTS_FILE)
        info = {"format": FORMAT, "version": VERSION, "flexff_version": flexff_version(),
                "config": config_record, "feature_names": feature_names,
                "label_names": label_names, "model_rate_hz": model_rate_hz,
                "scalers": {"features": feature_scaler.to_dict(),
                            "labels": label_scaler.to_dict()},
                "history": network.history,
                "state": [{"name": n, "shape": list(s)}
                          for n, s in zip(network.state_names(), network.state_shapes(1))],
                "weights_sha256": file_sha256(staging / WEIGHTS_FILE), **extra}
        for name, write in files.items():
            write(staging / name)
        (staging / RUN_FILE).write_text(json.dumps(info, indent=2) + "\n")
        for name in (WEIGHTS_FILE, *files, RUN_FILE):
            os.replace(staging / name, out / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    for name in (CHECKPOINT_FILE, BEST_FILE):
        (out / name).unlink(missing_ok=True)


def load_run(path: str | Path) -> Run:
    """Rebuild a run folder written by `learning.train.fit`."""
    path = Path(path)
    for name in (RUN_FILE, WEIGHTS_FILE):
        if not (path / name).is_file():
            if (path / CHECKPOINT_FILE).is_file():
                raise RunFolderError(f"{path} holds an unfinished training run ({name} is "
                                     f"missing): finish it with flexff train ... -o {path} "
                                     f"--resume")
            raise RunFolderError(f"{path} is not a finished training run ({name} is missing): "
                                 f"train one with flexff train ... -o {path}")
    again = f"train the model again into it with this flexff (flexff train ... -o {path} --force)"
    try:
        info = json.loads((path / RUN_FILE).read_text())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise RunFolderError(f"{path / RUN_FILE} is not valid JSON (damaged): {again}") from None
    if not isinstance(info, dict) or info.get("format") != FORMAT \
            or info.get("version") != VERSION:
        found = (info.get("format"), info.get("version")) if isinstance(info, dict) else None
        raise RunFolderError(f"{path / RUN_FILE}: format and version {found}, expected "
                             f"{FORMAT!r} version {VERSION}: {again}")
    try:
        config = RunConfig.read(info["config"])
        network = build_network(config.model, len(info["feature_names"]),
                                n_outputs=len(info.get("label_names", ["Fx", "Fy"])),
                                **config.architecture)
        scalers = [MinMaxScaler.from_dict(info["scalers"][k]) for k in ("features", "labels")]
        rate = float(info["model_rate_hz"])
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        raise RunFolderError(f"{path / RUN_FILE} is damaged ({type(error).__name__}: "
                             f"{' '.join(str(error).split())}): {again}") from None
    content = (path / WEIGHTS_FILE).read_bytes()
    listed = info.get("weights_sha256")  # runs written before it was recorded have none
    if listed is not None and hashlib.sha256(content).hexdigest() != listed:
        raise RunFolderError(f"{path / WEIGHTS_FILE} is not the file {RUN_FILE} was written with "
                             f"(its sha256 differs: truncated or replaced): {again}")
    try:
        network.load_state_dict(torch.load(io.BytesIO(content), map_location="cpu",
                                           weights_only=True))
    except Exception:
        raise RunFolderError(f"{path / WEIGHTS_FILE} is damaged or does not hold the weights of "
                             f"the network {RUN_FILE} describes: {again}") from None
    network.eval()
    return Run(path=path, config=config, network=network, feature_scaler=scalers[0],
               label_scaler=scalers[1], feature_names=info["feature_names"],
               model_rate_hz=rate, info=info)


# -- checkpoints ------------------------------------------------------------------------------
def start_run(out: Path, settings: dict[str, Any], resume: bool | None,
              force: bool) -> dict[str, Any] | None:
    """Check that training with `settings` may write into `out`; return the checkpoint to
    resume from, or None to start afresh.

    `resume` True: `out` must hold a checkpoint of the same settings; False: never resume;
    None: resume a checkpoint of the same settings, else as False. Without `force`, a folder
    holding a finished run, a checkpoint not resumed or anything else is refused; with it,
    training starts afresh and replaces a finished run's files once the new ones are complete.
    """
    if out.exists() and not out.is_dir():
        raise RunFolderError(f"{out} exists and is not a folder: give -o a folder")
    _remove_leftovers(out)
    try:
        checkpoint = load_checkpoint(out)
    except RunFolderError:
        if resume or not force:
            raise
        checkpoint = None
    if resume and checkpoint is None:
        raise RunFolderError(f"{out} holds no {CHECKPOINT_FILE} to resume from: train without "
                             f"--resume")
    if checkpoint is not None and resume is not False:
        differences = _differences(json.loads(checkpoint["settings"]), settings)
        if not differences:
            return checkpoint
        if resume:
            raise RunFolderError(
                f"{out / CHECKPOINT_FILE} was written with other settings ({'; '.join(differences)}"
                f"): resume with the same settings and data, or start again with --force")
    if force:
        return None
    if checkpoint is not None:
        raise RunFolderError(f"{out} holds an unfinished training run (checkpoint after epoch "
                             f"{checkpoint['epoch']} of {checkpoint['epochs']}): continue it "
                             f"with --resume (same settings), or start again with --force")
    if (out / RUN_FILE).is_file():
        raise RunFolderError(f"{out} holds a finished training run: train into another folder, "
                             f"or replace it with --force (its files stay until the new ones "
                             f"are complete)")
    held = sorted(p.name for p in out.iterdir()) if out.is_dir() else []
    if held:
        raise RunFolderError(f"{out} is not empty ({', '.join(held[:5])}"
                             f"{', ...' if len(held) > 5 else ''}): train into a new or empty "
                             f"folder, or into this one with --force")
    return None


def save_checkpoint(out: Path, checkpoint: dict[str, Any]) -> None:
    """Write checkpoint.pt atomically (see learning.train for what it holds)."""
    atomic_write(out / CHECKPOINT_FILE,
                 lambda tmp: torch.save({"format": CHECKPOINT_FORMAT, **checkpoint}, tmp))


def save_best(out: Path, state: dict[str, torch.Tensor], epoch: int, val_mse: float) -> None:
    """Write best.pt atomically: the weights of the best epoch so far, its number and loss."""
    atomic_write(out / BEST_FILE, lambda tmp: torch.save(
        {"epoch": epoch, "val_mse": val_mse,
         "state": {k: v.detach().cpu() for k, v in state.items()}}, tmp))


def load_checkpoint(out: Path) -> dict[str, Any] | None:
    """The checkpoint in `out`, or None; RunFolderError if it is unreadable."""
    path = out / CHECKPOINT_FILE
    if not path.is_file():
        return None
    try:
        checkpoint: dict[str, Any] = torch.load(path, map_location="cpu", weights_only=True)
        if checkpoint.get("format") != CHECKPOINT_FORMAT or \
                not all(k in checkpoint for k in CHECKPOINT_KEYS):
            raise ValueError
        if not isinstance(json.loads(checkpoint["settings"]).get("config"), dict):
            raise ValueError
    except Exception:
        raise RunFolderError(f"{path} is damaged or not a flexff checkpoint: start again with "
                             f"--force") from None
    return checkpoint


def _differences(found: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    """What differs between a checkpoint's settings and the wanted ones, in words."""
    lines = [f"{key}: {found['config'].get(key)!r} there, {value!r} here"
             for key, value in wanted["config"].items() if found["config"].get(key) != value]
    if found.get("data") != wanted["data"]:
        lines.append("the dataset differs (other files, or its manifest changed)")
    return lines


def _remove_leftovers(out: Path) -> None:
    """Delete what an interrupted write left: temporary files and staging folders."""
    if not out.is_dir():
        return
    for stale in out.glob(".*.tmp"):
        stale.unlink()
    for stale in out.glob(f"{STAGING}*"):
        shutil.rmtree(stale, ignore_errors=True)
