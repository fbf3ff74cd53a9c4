"""An ONNX graph's tensor sizes are bounded before memory is spent on them (fmu.limits): the
issue's 83-byte file whose input has the shape [1, 1e9] is refused by `flexff fmu build onnx`
in one line naming the limit and how to raise it (it used to name 10^9 elements until the
kernel killed it at 22.7 GB); a state tensor is bounded the same way."""

import json
import os
import resource
import subprocess
import sys

import onnx
from onnx import TensorProto
from onnx import helper as oh

from tests.helpers import REPOSITORY

MEMORY = 8 * 2**30  # the command's address space: the old code met this bound, not the kernel


def huge_graph(path, shape, state=False):
    """An Identity graph whose input and output have `shape` (and, with `state`, a state
    tensor pair of that shape beside a one-element input)."""
    tensors = [("x", "y", shape)]
    meta = {}
    if state:
        tensors = [("x", "y", [1]), ("h", "h_out", shape)]
        meta = {"state": json.dumps([{"input": "h", "output": "h_out"}])}
    graph = oh.make_graph(
        [oh.make_node("Identity", [i], [o]) for i, o, _ in tensors], "huge",
        [oh.make_tensor_value_info(i, TensorProto.FLOAT, s) for i, _, s in tensors],
        [oh.make_tensor_value_info(o, TensorProto.FLOAT, s) for _, o, s in tensors])
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 13)])
    oh.set_model_props(model, meta)
    onnx.save(model, path)
    return path


def build(tmp_path, graph):
    def bounded():
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))

    env = {**os.environ, "PYTHONPATH": str(REPOSITORY)}
    return subprocess.run([sys.executable, "-m", "flexff", "fmu", "build", "onnx", str(graph),
                           "-o", str(tmp_path / "huge.fmu")], capture_output=True, text=True,
                          env=env, preexec_fn=bounded, timeout=300)


def test_a_tiny_file_with_a_huge_tensor_is_refused(tmp_path):
    graph = huge_graph(tmp_path / "huge.onnx", [1, 10**9])
    assert graph.stat().st_size < 100
    done = build(tmp_path, graph)
    assert done.returncode == 2, done.stderr
    assert done.stderr == (f"flexff: error: {graph}: inputs 'x': 1,000,000,000 tensor elements "
                           f"(each an FMU variable), more than the limit of 100,000; if that is "
                           f"meant, raise it: FLEXFF_MAX_ONNX_ELEMENTS=1000000000 flexff ...\n")
    assert not (tmp_path / "huge.fmu").exists()


def test_a_huge_state_tensor_is_refused(tmp_path):
    done = build(tmp_path, huge_graph(tmp_path / "state.onnx", [10**5, 10**5], state=True))
    assert done.returncode == 2, done.stderr
    assert "state 'h': 10,000,000,000 tensor elements" in done.stderr
    assert len(done.stderr.splitlines()) == 1
