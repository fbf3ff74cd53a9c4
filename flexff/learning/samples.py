"""A CasADi Function of one sample evaluated on many: mapped in chunks over the granted cores,
compiled once a process has used it enough. Every floor above cosim evaluates its models,
features and priors this way.
"""

from __future__ import annotations

import functools
from typing import Any

import casadi as ca
import numpy as np

from flexff.cosim.executor import granted_cores
from flexff.fmu.compiled_function import compiled

MAP_CHUNK = 4096  # samples per call of a mapped Function (evaluate_samples)
# once a process has evaluated a Function on this many samples, evaluate_samples runs it
# compiled (fmu.compiled_function): compiling the hardware plant's inverse dynamics took 0.8 s
# once per machine, and saved 1.4 s on 1e5 samples (1.65 s interpreted, 0.21 s compiled; the
# directions features 1.31 s and 0.44 s); a test's few hundred samples stay interpreted
COMPILED_FROM = 20_000
_evaluated: dict[ca.Function, int] = {}  # samples each Function has been evaluated on


def evaluate_samples(function: ca.Function, *columns: np.ndarray) -> np.ndarray:
    """Evaluate a one-sample Function on n samples given as (n, k) arrays; returns (n, m).

    The samples go through one map of MAP_CHUNK samples, built once per Function, chunk by
    chunk (the last one padded with its last sample): building a map takes time in proportion
    to its size, so a map per call of another length cost as much again as the work (1e5
    samples of the full features: 1.87 s with a map of their own, 1.07 s in chunks). The map
    runs on every core granted and reads and writes numpy's memory in place (CasADi's
    buffer): converting its matrices to and from numpy took longer than the evaluation (1e5
    samples of the directions features: 0.93 s, 0.36 s in place, on two cores). From
    COMPILED_FROM samples evaluated in this process on, the Function runs compiled, with the
    same results."""
    n = columns[0].shape[0]
    inputs = [np.asarray(c, dtype=float).reshape(n, -1) for c in columns]
    _evaluated[function] = _evaluated.get(function, 0) + n
    buffer, evaluate = _chunk_map(function, granted_cores(),
                                  _evaluated[function] >= COMPILED_FROM).buffer()
    chunk = [np.empty((MAP_CHUNK, c.shape[1])) for c in inputs]  # column-major (k, chunk)
    result = np.empty((MAP_CHUNK, function.size1_out(0)))
    # the buffer's size comes with the memoryview (CasADi's stubs ask for it separately)
    for k, held in enumerate(chunk):
        buffer.set_arg(k, held.data)  # type: ignore[call-arg]
    buffer.set_res(0, result.data)  # type: ignore[call-arg]
    out = np.empty((n, function.size1_out(0)))
    for start in range(0, n, MAP_CHUNK):
        size = min(MAP_CHUNK, n - start)
        for held, column in zip(chunk, inputs):
            held[:size] = column[start:start + size]
            held[size:] = column[start + size - 1]
        evaluate()
        out[start:start + size] = result[:size]
    return out


@functools.lru_cache(maxsize=64)
def _chunk_map(function: ca.Function, threads: int, compile_it: bool) -> ca.Function:
    """`function`, its output made dense (the buffer holds the nonzeros only) and, with
    `compile_it`, compiled, mapped over MAP_CHUNK samples on `threads` threads."""
    if not function.sparsity_out(0).is_dense():
        inputs: list[Any] = function.sx_in() if function.is_a("SXFunction") else \
            function.mx_in()
        function = ca.Function(function.name(), inputs, [ca.densify(function.call(inputs)[0])])
    return (compiled(function) if compile_it else function).map(MAP_CHUNK, "thread", threads)
