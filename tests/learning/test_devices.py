"""Device mix-ups found without a GPU: every tensor a learning module creates names its device
(or takes another tensor's), and each network's forward pass stays on the device of its input
(the `meta` device: shapes without data, where a tensor made on the CPU cannot join)."""

import ast
from pathlib import Path

import pytest
import torch

from flexff.learning.models import NETWORKS, build_network, fit_linear_skip

LEARNING = Path(__file__).parents[2] / "learning"
FACTORIES = {"zeros", "ones", "empty", "full", "arange", "linspace", "rand", "randn",
             "randint", "eye", "tensor", "as_tensor"}
# modules that run on the CPU by design: export and its SI model, the CasADi bridge
CPU_ONLY = {"export.py", "deploy.py", "casadi_torch.py", "rigid.py"}


def factory_calls_without_device(source: str) -> list[int]:
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and isinstance(node.func.value, ast.Name) and node.func.value.id == "torch" \
                and node.func.attr in FACTORIES \
                and not any(k.arg == "device" for k in node.keywords):
            lines.append(node.lineno)
    return lines


def test_the_check_finds_a_factory_without_a_device():
    assert factory_calls_without_device("torch.ones(3, 1, dtype=torch.float64)") == [1]
    assert factory_calls_without_device("torch.ones(3, device=x.device)") == []


@pytest.mark.parametrize("module", sorted(p.name for p in LEARNING.glob("*.py")
                                          if p.name not in CPU_ONLY))
def test_learning_modules_create_tensors_on_a_named_device(module):
    """The crash of a CUDA run (torch.cat of a CPU tensor with CUDA ones) came from a tensor
    made without a device; each must name one (or be made like another, new_zeros)."""
    found = factory_calls_without_device((LEARNING / module).read_text())
    assert not found, f"learning/{module}: torch factory calls without device= at {found}"


@pytest.mark.parametrize("kind", sorted(NETWORKS))
@pytest.mark.parametrize("skip", [False, True])
def test_forward_passes_stay_on_the_device_of_their_input(kind, skip):
    if skip and NETWORKS[kind][1]:
        pytest.skip("the physics-guided network has no linear skip")
    network = build_network(kind, 7, n_outputs=2, linear_skip=skip).to("meta")
    out, state = network(torch.empty(3, 120, 7, device="meta"))
    assert out.device.type == "meta" and out.shape == (3, 120, 2)
    assert all(s.device.type == "meta" for s in state)
    step = network.step_form().to("meta")
    out, _ = step(torch.empty(1, 1, 7, device="meta"))
    assert out.device.type == "meta"


def test_the_linear_skip_is_fitted_on_the_cpu_and_lands_on_the_network():
    network = build_network("tcn", 3, n_outputs=2, linear_skip=True)
    x = torch.randn(500, 3, generator=torch.Generator().manual_seed(0))
    y = x @ torch.tensor([[1.0, -2.0], [0.5, 0.0], [0.0, 3.0]]) + torch.tensor([0.1, -0.2])
    fit_linear_skip(network, x, y)
    torch.testing.assert_close(network.linear.weight.T.double(), torch.tensor(
        [[1.0, -2.0], [0.5, 0.0], [0.0, 3.0]], dtype=torch.float64), atol=1e-5, rtol=0)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_a_network_trains_its_linear_skip_on_cuda():
    network = build_network("tcn", 3, n_outputs=2, linear_skip=True).to("cuda")
    x = torch.randn(500, 3, device="cuda")
    fit_linear_skip(network, x, 2 * x[:, :2])
    assert network.linear.weight.device.type == "cuda"
