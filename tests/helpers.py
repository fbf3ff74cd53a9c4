"""Helpers shared by the tests."""

import os
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import psutil

REPOSITORY = Path(__file__).resolve().parents[1]
# the Modelica Reference-FMUs, kept in the repository (README.md and LICENSE.txt beside them)
REFERENCE_FMUS = REPOSITORY / "flexff" / "cosim" / "examples" / "reference-fmus"
# a network FMU (its graph as generated C, the default) against onnxruntime's Python API:
# float32 sums in another order, 3e-7 of the largest force measured on the tiny test models
NETWORK_RTOL = 1e-6


def train_tiny_models(folder: Path, sizes: dict, seed: int) -> Path:
    """Small networks of each kind in `sizes` (name -> settings: a "model" kind, the name's
    where none, and architecture or preprocessing overrides), one epoch on a small synthetic
    set, exported as `folder`/<name>.onnx beside their run folders."""
    from flexff.learning.export import export
    from flexff.learning.synthetic import synthetic_dataset
    from flexff.learning.threads import torch_threads
    from flexff.learning.train import train

    data = synthetic_dataset(folder / "data", n_train=3, n_test=1, duration=3.0, rate_hz=100.0,
                             seed=seed)
    with torch_threads():
        for name, settings in sizes.items():
            overrides = {k: v for k, v in settings.items() if k != "model"}
            train(settings.get("model", name), "fast", data, folder / name, progress=False,
                  epochs=1, val_fraction=0.2, **overrides)
            export(folder / name, folder / f"{name}.onnx")
    return folder


def thesis_reference_window(steps: int) -> dict:
    """steps + 1 samples of the thesis evaluation reference's signals, from its 5 s mark:
    the learned feedforwards' test input."""
    from flexff.learning.dataset import REFERENCE_SIGNALS
    from flexff.plant.references import thesis_evaluation

    signals = thesis_evaluation().signals()
    return {name: signals[name][5000:5000 + steps + 1] for name in REFERENCE_SIGNALS}


def workspace_points(rng: np.random.Generator, n: int, radius: float = 0.05) -> np.ndarray:
    """n points spread over the workspace disc, its boundary included (2 x n)."""
    r = radius * np.sqrt(rng.uniform(0, 1, n))
    r[: max(1, n // 8)] = radius  # always test the edge
    a = rng.uniform(-np.pi, np.pi, n)
    return np.vstack([r * np.cos(a), r * np.sin(a)])


def rest_to_rest_moves(seed: int, seconds: float, rate: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk moves between random positions in +-0.045, each 0.3 to 0.8 s long and
    followed by a rest of 0.2 to 0.6 s, sampled at `rate`: time, position, velocity (exactly 0
    at rest) and acceleration."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1 / rate)
    x = np.zeros_like(t)
    start, here = 0.3, 0.0
    while start < seconds:
        to, span = rng.uniform(-0.045, 0.045), rng.uniform(0.3, 0.8)
        s = np.clip((t - start) / span, 0.0, 1.0)
        x = np.where(t >= start, here + (to - here) * (10 * s**3 - 15 * s**4 + 6 * s**5), x)
        start, here = start + span + rng.uniform(0.2, 0.6), to
    v, a = np.gradient(x, 1 / rate), np.gradient(np.gradient(x, 1 / rate), 1 / rate)
    v[np.abs(v) < 1e-12] = 0.0  # exactly at rest between the moves
    return t, x, v, a


def simulate(model, x0, params, times, current=(0.0, 0.0, 0.0), rtol=1e-12, atol=1e-14):
    """Tight-tolerance reference solution (CVODES, BDF/Newton) of the plant ODE at `times`."""
    import casadi as ca

    x = ca.SX.sym("x", model.n_states)
    ode = {"x": x, "ode": model.forward_dynamics(x, ca.DM(current), ca.DM(params))}
    solver = ca.integrator("reference", "cvodes", ode, float(times[0]), list(times[1:]),
                           {"abstol": atol, "reltol": rtol, "max_num_steps": 10**7})
    result = np.array(solver(x0=x0)["xf"])
    return np.column_stack([np.asarray(x0, dtype=float), result])


def run_readme_snippet(folder: Path, name: str) -> str:
    """The documentation's `<!-- NAME.py -->` block saved as NAME.py in `folder`, then its
    `<!-- NAME.sh -->` block run there with this Python first on the PATH; its output."""
    (folder / f"{name}.py").write_text(readme_block(f"{name}.py"))
    environment = {**os.environ, "PATH": f"{os.path.dirname(sys.executable)}:{os.environ['PATH']}"}
    done = subprocess.run(["bash", "-euo", "pipefail", "-c", readme_block(f"{name}.sh")],
                          cwd=folder, env=environment, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def readme_block(marker: str) -> str:
    """The fenced code block right after `<!-- marker -->` in README.md or a page of docs/,
    its `--8<-- "FILE"` lines (MkDocs snippets) replaced by FILE's text."""
    pages = [REPOSITORY / "README.md", *sorted((REPOSITORY / "docs").rglob("*.md"))]
    pattern = rf"<!-- {re.escape(marker)} -->\n```\w+\n(.*?)```"
    found = next(filter(None, (re.search(pattern, p.read_text(), re.DOTALL) for p in pages)),
                 None)
    assert found, f"no page has a code block after <!-- {marker} -->"
    return re.sub(r'^--8<-- "([^"]+)"\n', lambda m: (REPOSITORY / m[1]).read_text(),
                  found.group(1), flags=re.MULTILINE)


def matlab_v73_header(path: Path) -> None:
    """The 128-byte header of a MATLAB v7.3 file (version 0x0200, little endian), written over
    the start of the HDF5 file at `path` (made with a 512-byte user block)."""
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Jan  1 00:00:00 2026 HDF5"
    with open(path, "r+b") as handle:
        handle.write(text.ljust(116, b" ") + bytes(8) + b"\x00\x02IM")


def assert_descendants_end_with(process: subprocess.Popen,
                                started: Callable[[list[psutil.Process]], bool],
                                settle_s: float = 0.0, within_s: float = 5.0) -> None:
    """Wait until `started(descendants of process)`, then `settle_s` more (into a hang, say),
    SIGKILL `process` alone, and assert that every one of those descendants ends within
    `within_s` (any left are killed after the check)."""
    descendants: list[psutil.Process] = []
    try:
        deadline = time.monotonic() + 60
        while not _holds(started, descendants):
            assert process.poll() is None and time.monotonic() < deadline
            descendants = psutil.Process(process.pid).children(recursive=True)
            time.sleep(0.05)
        time.sleep(settle_s)
        process.kill()
        process.wait()
        _, alive = psutil.wait_procs(descendants, timeout=within_s)
        assert not alive, f"{alive} outlived {process.pid}"
    finally:  # the test's own processes, should the check fail
        if process.poll() is None:
            process.kill()
        for descendant in descendants:
            if descendant.is_running():
                descendant.kill()


def _holds(started: Callable[[list[psutil.Process]], bool],
           descendants: list[psutil.Process]) -> bool:
    try:
        return started(descendants)
    except psutil.NoSuchProcess:  # one ended since it was listed: list them again
        return False
