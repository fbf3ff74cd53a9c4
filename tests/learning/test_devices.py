"""Training, resuming, the networks and their export on a device other than the CPU.

Without a GPU the device is emulated (tests.learning.fake_device): every tensor keeps its
side, and an operation mixing the two fails as it does on CUDA. The emulated runs must equal
the CPU's exactly, as the same arithmetic runs underneath. With CUDA the fast preset also
trains on the GPU itself (skipped here)."""

import json
import warnings
from contextlib import nullcontext

import numpy as np
import pytest
import torch

import flexff.learning.train as training
from flexff.fmu.errors import InputError
from flexff.learning.export import export
from flexff.learning.models import build_network, fit_linear_skip
from flexff.learning.run_folder import load_run
from flexff.learning.train import train
from tests.learning.fake_device import DEVICE, FakeDevice

pytestmark = pytest.mark.usefixtures("few_threads")

# the fast preset's networks, smaller; the LSTM and TCN keep their linear skip
TINY = {"lstm": {"hidden": 8}, "cnn-lstm": {"hidden": 8, "conv_channels": [4, 4, 2]},
        "tcn": {"channels": 8, "levels": 2}, "pgnn": {"channels": 8, "levels": 2}}
CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")


def _weights(path):
    return load_run(path).network.state_dict()


def _same(a, b):
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("kind, extra", [
    *(pytest.param(kind, {}, id=kind) for kind in TINY),
    pytest.param("tcn", {"force_input": True}, id="tcn-force")])
def test_training_on_another_device_mixes_no_tensors_and_equals_the_cpus(data, tmp_path,
                                                                          kind, extra):
    on_cpu = train(kind, "fast", data, tmp_path / "cpu", progress=False, epochs=2,
                   device="cpu", **TINY[kind], **extra)
    with FakeDevice() as device:
        on_device = train(kind, "fast", data, tmp_path / "device", progress=False, epochs=2,
                          device=str(DEVICE), **TINY[kind], **extra)
    assert device.checked > 1000  # the mode saw the training
    assert on_device["device"] == str(DEVICE)
    assert on_device["history"]["train"] == on_cpu["history"]["train"]
    assert _same(_weights(tmp_path / "device"), _weights(tmp_path / "cpu"))


def test_a_run_trained_on_another_device_exports(data, tmp_path):
    with FakeDevice():
        train("tcn", "fast", data, tmp_path / "run", progress=False, epochs=1,
              device=str(DEVICE), **TINY["tcn"])
    assert export(tmp_path / "run", tmp_path / "tcn.onnx").is_file()


def _on(device):
    """The block on `device`: the emulated one, or the CPU."""
    return FakeDevice() if device == str(DEVICE) else nullcontext()


def _cut_and_resumed(data, run, monkeypatch, first, then, **settings):
    """The tiny LSTM's two epochs into `run`: interrupted after the first on device `first`
    (its checkpoint written), then resumed on `then`; the resumed run's metrics."""
    real = training.Checkpoints.epoch_done

    def stop_after_one(self, epochs, network, optimizer, rng, history, *rest):
        real(self, epochs, network, optimizer, rng, history, *rest)
        raise KeyboardInterrupt

    monkeypatch.setattr(training.Checkpoints, "epoch_done", stop_after_one)
    with _on(first), pytest.raises(KeyboardInterrupt):
        train("lstm", "fast", data, run, progress=False, epochs=2, device=first,
              checkpoint_every=1, **settings, **TINY["lstm"])
    monkeypatch.setattr(training.Checkpoints, "epoch_done", real)
    with _on(then):
        return train("lstm", "fast", data, run, progress=False, epochs=2, device=then,
                     **settings, **TINY["lstm"])


@pytest.mark.parametrize("first,then", [("cpu", str(DEVICE)), (str(DEVICE), "cpu")])
def test_a_checkpoint_resumes_on_another_device_to_the_same_weights(data, tmp_path,
                                                                    monkeypatch, first, then):
    whole = tmp_path / "whole"
    train("lstm", "fast", data, whole, progress=False, epochs=2, device="cpu", **TINY["lstm"])
    resumed = _cut_and_resumed(data, tmp_path / "cut", monkeypatch, first, then)
    assert len(resumed["history"]["train"]) == 2
    assert _same(_weights(tmp_path / "cut"), _weights(whole))


@pytest.mark.parametrize("kind", ["tcn", "cnn-lstm"])
def test_the_step_form_of_a_network_on_another_device_mixes_no_tensors(kind):
    network = build_network(kind, 5, linear_skip=True, **TINY[kind]).eval()
    x, y = torch.randn(1, 30, 5), torch.randn(30, 2)
    expected = network.step_form()(x)[0]
    with FakeDevice(), torch.no_grad():
        network.to(DEVICE)
        fit_linear_skip(network, x.to(DEVICE)[0], y.to(DEVICE))
        stepped = network.step_form()
        state, outputs = None, []
        for t in range(x.shape[1]):
            out, state = stepped(x[:, t:t + 1].to(DEVICE), state)
            outputs.append(out.cpu())
    assert not torch.equal(torch.cat(outputs, dim=1), expected)  # the skip was fitted
    assert torch.cat(outputs, dim=1).shape == expected.shape


def test_the_emulated_device_finds_a_mix_up():
    with FakeDevice(), pytest.raises(RuntimeError, match="same device"):
        torch.cat([torch.ones(2, 1).to(DEVICE), torch.ones(2, 1)], dim=1)


def test_cuda_asked_for_without_cuda_is_refused_before_any_work(data, tmp_path, monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(training, "load_dataset", lambda path: pytest.fail("data loaded"))
    with pytest.raises(InputError, match="CUDA is not available"):
        train("lstm", "fast", data, tmp_path / "run", progress=False, device="cuda")


@CUDA
@pytest.mark.parametrize("kind", list(TINY))
def test_the_fast_preset_trains_on_cuda_as_on_the_cpu(data, tmp_path, kind):
    runs = {device: train(kind, "fast", data, tmp_path / device, progress=False, epochs=3,
                          device=device) for device in ("cpu", "cuda")}
    assert runs["cuda"]["device"].startswith("cuda")
    assert np.isfinite(runs["cuda"]["test_mse"])
    # other kernels, other rounding: the same loss to a few percent, not bit for bit
    assert runs["cuda"]["test_mse"] == pytest.approx(runs["cpu"]["test_mse"], rel=0.2)
    export(tmp_path / "cuda", tmp_path / f"{kind}.onnx")
    assert json.loads((tmp_path / "cuda" / "metrics.json").read_text())["device"] == "cuda"


@CUDA
@pytest.mark.parametrize("kind", list(TINY))
def test_steps_replayed_from_cuda_graphs_train_as_eager_ones(data, tmp_path, kind):
    with warnings.catch_warnings():  # a failed capture warns: it would fall back unseen
        warnings.filterwarnings("error", "training steps run eagerly", RuntimeWarning)
        runs = {graphs: train(kind, "fast", data, tmp_path / str(graphs), progress=False,
                              epochs=3, device="cuda", cuda_graphs=graphs)
                for graphs in (True, False)}
    assert runs[True]["cuda_graphs"] and not runs[False]["cuda_graphs"]
    assert runs[True]["test_mse"] == pytest.approx(runs[False]["test_mse"], rel=0.05)


@CUDA
@pytest.mark.parametrize("first,then", [("cuda", "cpu"), ("cpu", "cuda"), ("cuda", "cuda")])
def test_a_checkpoint_of_replayed_steps_resumes_anywhere(data, tmp_path, monkeypatch, first,
                                                          then):
    whole = train("lstm", "fast", data, tmp_path / "whole", progress=False, epochs=2,
                  device=then, **TINY["lstm"])
    resumed = _cut_and_resumed(data, tmp_path / "cut", monkeypatch, first, then,
                               cuda_graphs=True)
    assert resumed["cuda_graphs"] == (then == "cuda")
    assert resumed["test_mse"] == pytest.approx(whole["test_mse"], rel=0.05)


def test_the_command_lines_devices_are_the_librarys():
    from flexff.cli.shared import DEVICES as OFFERED
    from flexff.learning.devices import DEVICES

    assert OFFERED == DEVICES


@pytest.mark.parametrize("command", [
    ["train", "--model", "lstm", "--data", "DATA", "-o", "OUT"],
    ["evaluate", "-o", "OUT"], ["demo", "-o", "OUT"]])
def test_cuda_without_cuda_is_one_line_and_exit_code_2(command, tmp_path, monkeypatch, capsys):
    from flexff.cli import main

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.chdir(tmp_path)
    assert main([*command, "--device", "cuda"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "CUDA is not available" in lines[0]
    assert not (tmp_path / "OUT").exists() or not any((tmp_path / "OUT").iterdir())
