"""The training step, eager and replayed (learning.training_step).

Without a GPU the capture is emulated: `EmulatedGraphs.capture` computes the step's outputs
once and puts the network, Adam and the random generator back, as a real capture runs
nothing; each replay runs the step again on the captured inputs and writes its results into
the first outputs, as a graph overwrites its own. The steps must then equal eager ones bit
for bit, through shape changes and a state carried from step to step. On CUDA the real
graphs run (tests/learning/test_devices.py). The capturable Adam a graph needs runs on the CPU
too, through torch's own code, once the CPU is on torch's list of devices it allows."""

import copy
import importlib

import pytest
import torch

import flexff.learning.train as training
from flexff.learning.models import build_network
from flexff.learning.training_step import (
    TrainingStep,
    adam,
    load_state,
    portable_state,
    set_learning_rate,
)


@pytest.fixture
def capturable_on_the_cpu(monkeypatch):
    """torch's capturable Adam allowed on the CPU: it refuses the CPU by a list alone."""
    modules = [importlib.import_module(f"torch.optim.{name}") for name in ("adam", "optimizer")]
    allowed = modules[1]._get_capturable_supported_devices

    def with_the_cpu(supports_xla=True):
        return [*allowed(supports_xla), "cpu"]

    for module in modules:
        monkeypatch.setattr(module, "_get_capturable_supported_devices", with_the_cpu)


class EmulatedGraphs:
    """CudaGraphs' interface on the CPU (see the module)."""

    def __init__(self, network, optimizer, fail=False):
        self.network, self.optimizer, self.fail = network, optimizer, fail
        self.captures = self.replays = 0

    def warm_up(self, work):
        return work()

    def capture(self, work):
        if self.fail:
            raise RuntimeError("operation not permitted when stream is capturing\nmore")
        weights = copy.deepcopy(self.network.state_dict())
        moments = copy.deepcopy(self.optimizer.state_dict())
        generator = torch.get_rng_state()
        loss, state = work()
        self.network.load_state_dict(weights)
        self.optimizer.load_state_dict(moments)
        torch.set_rng_state(generator)
        self.captures += 1

        def replay():
            self.replays += 1
            new_loss, new_state = work()
            loss.copy_(new_loss)
            for old, new in zip(state, new_state):
                old.copy_(new)

        return (loss, state), replay


def _batches(network, n=9):
    """Steps of two batch shapes, interleaved, the state of each carried on."""
    generator = torch.Generator().manual_seed(3)
    for k in range(n):
        batch = 3 if k % 3 else 2
        x = torch.randn(batch, 7, 4, generator=generator)
        y = torch.randn(batch, 7, 2, generator=generator)
        mask = torch.rand(batch, 7, generator=generator) > 0.3
        yield batch, x, y, mask


SIZES = {"lstm": {"hidden": 5}, "cnn-lstm": {"hidden": 5, "conv_channels": [3, 2],
                                             "conv_kernels": [3, 2]},
         "tcn": {"channels": 3, "levels": 2, "kernel": 2}, "pgnn": {"channels": 3, "levels": 2}}


def _network(kind, dropout=0.2):
    torch.manual_seed(0)
    return build_network(kind, 4, dropout=dropout, linear_skip=True, **SIZES[kind])


def _train(kind, graphs_of=None, captured=False):
    network = _network(kind)
    optimizer = adam(network, 1e-2, captured)
    graphs = graphs_of(network, optimizer) if graphs_of else None
    step = TrainingStep(network, optimizer, 0.5, graphs)
    states, losses = {}, []
    for k, (batch, x, y, mask) in enumerate(_batches(network)):
        set_learning_rate(optimizer, 1e-2 / (k + 1))
        state = states.get(batch, network.initial_state(batch))
        loss, state = step(x, state, y, mask)
        states[batch] = tuple(s.clone() for s in state)
        losses.append(float(loss))
    return network, losses, graphs


@pytest.mark.parametrize("kind", list(SIZES))
def test_replayed_steps_equal_eager_ones(kind):
    eager, eager_losses, _ = _train(kind)
    replayed, losses, graphs = _train(kind, EmulatedGraphs)
    assert graphs.captures == 2 and graphs.replays == 7  # 9 steps, a warm-up per shape
    assert losses == eager_losses
    assert all(torch.equal(a, b) for a, b in zip(replayed.state_dict().values(),
                                                  eager.state_dict().values()))


def test_a_failed_capture_warns_once_and_steps_eagerly():
    eager, eager_losses, _ = _train("lstm")
    with pytest.warns(RuntimeWarning, match="capture as a CUDA graph failed .operation not "
                                            "permitted when stream is capturing.$") as caught:
        stepped, losses, _ = _train(
            "lstm", lambda network, optimizer: EmulatedGraphs(network, optimizer, fail=True))
    assert len(caught) == 1
    assert losses == eager_losses
    assert all(torch.equal(a, b) for a, b in zip(stepped.state_dict().values(),
                                                  eager.state_dict().values()))


def test_the_learning_rate_is_set_in_place_where_a_graph_reads_it():
    network = build_network("tcn", 4, channels=4, levels=1)
    optimizer = adam(network, 1e-3, captured=False)
    optimizer.param_groups[0]["lr"] = rate = torch.tensor(1e-3)
    set_learning_rate(optimizer, 5e-4)
    assert optimizer.param_groups[0]["lr"] is rate and float(rate) == pytest.approx(5e-4)


def _close(a, b):
    return all(torch.allclose(x, y, rtol=1e-4, atol=1e-6) for x, y in
               zip(a.state_dict().values(), b.state_dict().values()))


@pytest.mark.parametrize("kind", list(SIZES))
def test_a_capturable_adam_with_its_rate_in_a_tensor_steps_as_a_plain_one(
        capturable_on_the_cpu, kind):
    plain, plain_losses, _ = _train(kind)
    replayed, losses, graphs = _train(kind, EmulatedGraphs, captured=True)
    assert graphs.replays == 7
    assert losses == pytest.approx(plain_losses, rel=1e-5)
    assert _close(replayed, plain)


@pytest.mark.parametrize("first, then", [(True, False), (False, True)])
def test_an_optimizer_state_moves_between_captured_and_plain_steps(capturable_on_the_cpu,
                                                                    first, then):
    def steps(network, optimizer, batches):
        step = TrainingStep(network, optimizer, 0.5, None)
        for batch, x, y, mask in batches:
            step(x, network.initial_state(batch), y, mask)

    batches = list(_batches(None, 6))
    whole = _network("lstm", dropout=0.0)
    steps(whole, adam(whole, 1e-2, first), batches)
    moved = _network("lstm", dropout=0.0)
    optimizer = adam(moved, 1e-2, first)
    steps(moved, optimizer, batches[:3])
    state = portable_state(optimizer)
    assert all(type(group["lr"]) is float and not group["capturable"]
               for group in state["param_groups"])
    then_optimizer = adam(moved, 1.0, then)
    load_state(then_optimizer, state, then)
    assert all(float(group["lr"]) == pytest.approx(1e-2) and group["capturable"] == then
               for group in then_optimizer.param_groups)
    steps(moved, then_optimizer, batches[3:])
    assert _close(moved, whole)


@pytest.mark.parametrize("kind, sizes", [("lstm", {"hidden": 8}),
                                         ("tcn", {"channels": 8, "levels": 2})])
def test_the_epochs_of_a_training_replaying_graphs_train_as_eager_ones(
        capturable_on_the_cpu, monkeypatch, data, tmp_path, kind, sizes):
    """learning.train's own epochs (the recurrent one carrying a graph's state from chunk to
    chunk, the window one), checkpoints and schedule, with the graphs emulated on the CPU
    (on the CPU also where CUDA is: its kernels round otherwise): each step's outputs must
    be used before the next replay overwrites them."""
    graphs = []

    def step(network, optimizer, grad_clip, cuda_graphs):
        graphs.append(EmulatedGraphs(network, optimizer) if cuda_graphs else None)
        return TrainingStep(network, optimizer, grad_clip, graphs[-1])

    monkeypatch.setattr(training, "_replays_graphs", lambda config, _: config.cuda_graphs)
    monkeypatch.setattr(training, "CudaGraphs", object)
    monkeypatch.setattr(training, "TrainingStep", step)
    runs = {replayed: training.train(kind, "fast", data, tmp_path / str(replayed),
                                     progress=False, epochs=3, checkpoint_every=1, device="cpu",
                                     batch_size=2, cuda_graphs=replayed, **sizes)
            for replayed in (False, True)}
    assert graphs[0] is None and graphs[1].captures >= 1 and graphs[1].replays >= 6
    assert runs[True]["cuda_graphs"] and not runs[False]["cuda_graphs"]
    for key in ("train", "val"):  # the capturable Adam rounds otherwise (see above)
        assert runs[True]["history"][key] == pytest.approx(runs[False]["history"][key],
                                                           rel=1e-4)
    assert runs[True]["test_mse"] == pytest.approx(runs[False]["test_mse"], rel=1e-4)
