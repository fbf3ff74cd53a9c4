"""Random FMI 2.0 call sequences (tests/fmu_fuzz_driver.py) against each kind of flexff FMU:
the plant, the controller, the learned feedforward step by step and precomputed.

Each batch of sequences runs in a subprocess, so that a crash or a hang of the FMU is a test
failure that names the seed and shows the calls of the sequence; a sequence replays alone
from its seed (every report says how). The default run fuzzes 500 sequences per kind on the
normal build (about 12 s in all, the FMUs cached); the slow one 10^4 per kind on a build with
`-fsanitize=address,undefined` (fmu.compile.sanitizer_flags), where any sanitizer report fails.
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import onnx
import pytest
from fmpy import extract, read_model_description
from onnx import TensorProto
from onnx import helper as oh

from flexff.controllers.features import feature_names
from flexff.controllers.feedback import controller_system
from flexff.controllers.learned_feedforward import learned_feedforward_system
from flexff.fmu.build import build_fmu
from flexff.fmu.compile import SANITIZE_ENV, compiler
from flexff.plant.system import plant_system

DRIVER = Path(__file__).parents[1] / "fmu_fuzz_driver.py"
KINDS = ("plant", "controller", "feedforward-step", "feedforward-precomputed")
FOREIGN = {"plant": "controller", "controller": "plant",
           "feedforward-step": "feedforward-precomputed", "feedforward-precomputed": "plant"}
STEP = 1e-3
MODEL_RATE_HZ = 250.0  # the tiny model runs every 4 steps
TABLE_ROWS = 48  # a multiple of 4: the precomputed table ends at a call point of the model
FAST_SEQUENCES = 500  # per kind, in the default run
# Errors the fast run must meet, per kind (the defects of issue 14 and the checks that fixed
# them): a fuzzer that stops reaching them has lost its power, not found a bug.
REACHED = {
    "plant": ("Initial output", "RK4 sub-steps of max_substep", "corrupt state:",
              "belongs to another model"),
    "controller": ("corrupt state:", "belongs to another model"),
    "feedforward-step": ("The network's input", "The network returned",
                         "corrupt state: network step counter"),
    "feedforward-precomputed": ("precomputation table (# rows) ends at",
                                "past the precomputation table", "is not the time",
                                "corrupt state: network step counter"),
}
SLOW_SEQUENCES = 10_000  # per kind, sanitized
SLOW_BATCH = 1000


def tiny_feedforward_graph(path: Path, prior: str) -> Path:
    """A learned feedforward as flexff's export writes it, small and untrained: 63 features
    in, tanh(z) + h + 0 sqrt(4 - z^2) out for z = features W, with a float32 state h
    (h_out = h / 2 + the sum of the tanh), the export's metadata (feature names included).
    The square root makes the result NaN for large inputs, as a real network's may be."""
    names = feature_names("full")
    weights = 1e-2 * np.random.default_rng(7).standard_normal((len(names), 2))
    nodes = [
        oh.make_node("MatMul", ["inputs", "w"], ["z"]),
        oh.make_node("Tanh", ["z"], ["t"]),
        oh.make_node("Cast", ["h"], ["h64"], to=TensorProto.DOUBLE),
        oh.make_node("Add", ["t", "h64"], ["smooth"]),
        oh.make_node("Mul", ["z", "z"], ["z2"]),
        oh.make_node("Sub", ["four", "z2"], ["room"]),
        oh.make_node("Sqrt", ["room"], ["root"]),
        oh.make_node("Mul", ["root", "zero"], ["nan_if_large"]),
        oh.make_node("Add", ["smooth", "nan_if_large"], ["forces"]),
        oh.make_node("Constant", [], ["axes"],
                 value=oh.make_tensor("axes", TensorProto.INT64, [1], [0])),
        oh.make_node("ReduceSum", ["t", "axes"], ["sum"], keepdims=1),
        oh.make_node("Cast", ["sum"], ["sum32"], to=TensorProto.FLOAT),
        oh.make_node("Constant", [], ["half"],
                 value=oh.make_tensor("half", TensorProto.FLOAT, [], [0.5])),
        oh.make_node("Mul", ["h", "half"], ["decayed"]),
        oh.make_node("Add", ["decayed", "sum32"], ["h_out"]),
    ]
    graph = oh.make_graph(nodes, "tiny_feedforward", [
        oh.make_tensor_value_info("inputs", TensorProto.DOUBLE, ["time", len(names)]),
        oh.make_tensor_value_info("h", TensorProto.FLOAT, [1, 2])], [
        oh.make_tensor_value_info("forces", TensorProto.DOUBLE, ["time", 2]),
        oh.make_tensor_value_info("h_out", TensorProto.FLOAT, [1, 2])],
        initializer=[oh.make_tensor("w", TensorProto.DOUBLE, list(weights.shape),
                                    weights.ravel().tolist()),
                     oh.make_tensor("four", TensorProto.DOUBLE, [], [4.0]),
                     oh.make_tensor("zero", TensorProto.DOUBLE, [], [0.0])])
    model = oh.make_model(graph, opset_imports=[oh.make_opsetid("", 17)], ir_version=8)
    oh.set_model_props(model, {
        "format": "flexff-feedforward", "model_kind": "tiny", "feature_set": "full",
        "input_kind": "features", "prior": prior, "input_signals": json.dumps(names),
        "output_signals": json.dumps(["Fx_ff", "Fy_ff"]), "sample_rate_hz": repr(MODEL_RATE_HZ),
        "state": json.dumps([{"input": "h", "output": "h_out", "shape": [1, 2],
                              "initial": "zeros"}])})
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def circle_reference(rows: int = TABLE_ROWS) -> dict[str, np.ndarray]:
    """A 1 Hz circle of radius 10 mm about the centre, sampled at every step."""
    t, w, r = np.arange(rows) * STEP, 2 * np.pi, 0.01
    c, s = np.cos(w * t), np.sin(w * t)
    return {"x_ref": r * c, "y_ref": r * s, "vx_ref": -r * w * s, "vy_ref": r * w * c,
            "ax_ref": -r * w**2 * c, "ay_ref": -r * w**2 * s}


def build_fuzz_fmus(folder: Path) -> dict[str, Path]:
    """The FMU of each kind, by the project's builders (the feedforwards on tiny models)."""
    systems = {
        "plant": lambda: plant_system("hardware"),
        "controller": lambda: controller_system("hardware"),
        "feedforward-step": lambda: learned_feedforward_system(
            tiny_feedforward_graph(folder / "step.onnx", "none"), STEP),
        "feedforward-precomputed": lambda: learned_feedforward_system(
            tiny_feedforward_graph(folder / "precomputed.onnx", "rigid-body"), STEP,
            circle_reference()),
    }
    return {kind: build_fmu(system(), folder / f"{kind}.fmu") for kind, system in systems.items()}


def _scale(name: str, start: float) -> float:
    """A typical size of a variable's values, for inputs that make sense."""
    if name.endswith("_ref"):
        return {"x": 0.01, "y": 0.01, "v": 0.05, "a": 0.5}[name[0]]
    if name.startswith("theta"):
        return 0.01
    return abs(start) if start else 1.0


def fuzz_spec(fmu: Path, folder: Path, kind: str) -> dict:
    """What the driver needs of an FMU: extracted into `folder`."""
    unzipped = Path(extract(str(fmu), unzipdir=str(folder)))
    md = read_model_description(str(fmu))
    identifier = md.coSimulation.modelIdentifier
    library = next((unzipped / "binaries").glob(f"*/{identifier}.so"))
    reals, seed_vr = [], None
    for v in md.modelVariables:
        if v.type == "Integer":
            seed_vr = v.valueReference
            continue
        role = {"parameter": "parameter", "input": "input", "output": "output",
                "local": "state"}[v.causality]
        role = "max_substep" if v.name == "max_substep" else role
        start = float(v.start) if v.start is not None else 0.0
        reals.append({"vr": v.valueReference, "name": v.name, "role": role, "start": start,
                      "scale": _scale(v.name, start)})
    table = unzipped / "resources" / "table.csv"
    return {
        "kind": kind, "library": str(library), "guid": md.guid,
        "resources": (unzipped / "resources").as_uri(), "step": STEP,
        "n_real": len(reals), "seed_vr": seed_vr, "reals": reals,
        "table": np.loadtxt(table, delimiter=",", skiprows=1, ndmin=2).tolist()
        if table.exists() else None,
    }


def write_specs(fmus: dict[str, Path], folder: Path) -> dict[str, Path]:
    """spec.json of each kind, each offered the states of another kind ("foreign")."""
    specs = {kind: fuzz_spec(fmu, folder / kind, kind) for kind, fmu in fmus.items()}
    paths = {}
    for kind, spec in specs.items():
        foreign = specs[FOREIGN[kind]]
        spec["foreign"] = {k: foreign[k] for k in ("library", "guid", "resources", "step")}
        paths[kind] = folder / kind / "spec.json"
        paths[kind].write_text(json.dumps(spec))
    return paths


def sanitizer_environment() -> dict[str, str]:
    """The environment that loads a sanitized FMU into Python: the runtimes preloaded, leak
    detection off (the interpreter's own allocations are not freed at exit), and every report
    fatal with its own exit status."""
    runtimes = []
    for name in ("libasan.so", "libubsan.so"):
        found = subprocess.run([compiler(), f"-print-file-name={name}"], capture_output=True,
                               text=True).stdout.strip()
        if not os.path.isabs(found):
            pytest.skip(f"{compiler()} has no {name}")
        runtimes.append(found)
    return {**os.environ, "LD_PRELOAD": " ".join(runtimes),
            "ASAN_OPTIONS": "detect_leaks=0:halt_on_error=1:exitcode=86",
            "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1:exitcode=87"}


SANITIZER_TEXT = ("AddressSanitizer", "UndefinedBehaviorSanitizer", "LeakSanitizer",
                  "runtime error:")


def run_batch(spec: Path, seed: int, count: int, timeout: float,
              env: dict[str, str] | None = None) -> dict:
    """Run `count` sequences from `seed` in a subprocess; its summary, or pytest.fail with the
    seed, the calls of the failing sequence and the way to replay it."""
    trace = spec.parent / f"trace-{seed}.txt"
    command = [sys.executable, str(DRIVER), str(spec), "--seed", str(seed), "--count",
               str(count), "--trace", str(trace)]
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=env)
        problem, stdout, stderr = None, result.stdout, result.stderr
        if result.returncode != 0:
            problem = f"exit status {result.returncode}"
        elif any(text in stderr for text in SANITIZER_TEXT):
            problem = "a sanitizer report"
    except subprocess.TimeoutExpired as exc:
        problem = f"a hang: no result after {timeout:g} s"
        stdout, stderr = _text(exc.stdout), _text(exc.stderr)
    summary = _summary(stdout)
    if problem is None and summary is not None:
        return summary
    calls = trace.read_text(errors="replace").splitlines() if trace.exists() else []
    failed = calls[0].removeprefix("# seed ") if calls else "?"
    replay = [*command[:3], "--seed", failed, "--count", "1", "--trace", "/dev/stdout"]
    pytest.fail(
        f"FMI fuzzer, {spec.parent.name}: {problem or 'no summary'} in the sequence of seed "
        f"{failed}{': ' + summary['violation'] if summary and 'violation' in summary else ''}\n"
        f"replay: {' '.join(map(shlex.quote, replay))}"
        f"{' (with LD_PRELOAD, ASAN_OPTIONS, UBSAN_OPTIONS of the sanitized run)' if env else ''}\n"
        f"--- the sequence's calls (last 60) ---\n" + "\n".join(calls[-60:]) +
        f"\n--- stderr (last 3000 characters) ---\n{stderr[-3000:]}", pytrace=False)


def _text(data) -> str:
    return data.decode(errors="replace") if isinstance(data, bytes) else (data or "")


def _summary(stdout: str) -> dict | None:
    lines = stdout.strip().splitlines()
    try:
        return json.loads(lines[-1]) if lines else None
    except json.JSONDecodeError:
        return None


@pytest.fixture(scope="module")
def specs(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("fuzz")
    return write_specs(build_fuzz_fmus(folder), folder)


@pytest.mark.parametrize("kind", KINDS)
def test_random_call_sequences_do_not_crash(specs, kind):
    summary = run_batch(specs[kind], seed=0, count=FAST_SEQUENCES, timeout=120)
    assert summary["sequences"] == FAST_SEQUENCES
    assert summary["statuses"]["ok"] > 0 and summary["statuses"]["error"] > 0
    missed = [text for text in REACHED[kind]
              if not any(text in error for error in summary["errors"])]
    assert not missed, f"the fuzzer no longer reaches {missed}"


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_random_call_sequences_under_address_and_ub_sanitizers(tmp_path_factory, kind):
    env = sanitizer_environment()
    folder = tmp_path_factory.mktemp(f"fuzz-asan-{kind}")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(SANITIZE_ENV, "address,undefined")
        fmus = build_fuzz_fmus(folder)
    spec = write_specs(fmus, folder)[kind]
    binary = Path(json.loads(spec.read_text())["library"]).read_bytes()
    assert b"__asan_" in binary and b"__ubsan_" in binary  # really the sanitized build
    seeds = range(0, SLOW_SEQUENCES, SLOW_BATCH)
    with ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1))) as pool:
        summaries = list(pool.map(lambda s: run_batch(spec, s, SLOW_BATCH, 1800, env), seeds))
    assert sum(s["sequences"] for s in summaries) == SLOW_SEQUENCES
    calls = sum(s["calls"] for s in summaries)
    errors = {e for s in summaries for e in s["errors"]}
    print(f"{kind}: {SLOW_SEQUENCES} sequences, {calls} calls, {len(errors)} kinds of error "
          f"message, no crash, no sanitizer report")
