"""Building FMUs: validation, archive content, rebuild from sources/, cache, generated code."""

import subprocess
import sys
import time
import zipfile

import casadi as ca
import fmpy
import fmpy.validation
import numpy as np
import pytest
from fmpy import read_model_description

from flexff.fmu import build_fmu, fmu_key
from flexff.fmu.codegen import generate_model_c
from flexff.fmu.compile import SANITIZE_ENV, sanitizer_flags
from flexff.fmu.layout import make_layout
from flexff.fmu.system import System, Variable
from flexff.fmu.validation import FMI2_CS_FUNCTIONS, validate_fmu
from tests.fmu_toys import build_toy, discrete_pi, duffing
from tests.helpers import REPOSITORY
from tests.runners import run_fmu

TOYS = {"duffing": duffing, "discrete_pi": discrete_pi}


@pytest.fixture(scope="module", params=list(TOYS))
def toy_fmu(request, tmp_path_factory):
    return build_toy(TOYS[request.param](), tmp_path_factory)


def test_fmpy_validation_finds_no_problem(toy_fmu):
    assert fmpy.validation.validate_fmu(str(toy_fmu)) == []


def test_our_validation_finds_no_problem(toy_fmu):
    assert validate_fmu(toy_fmu) == []


def test_validation_reports_a_broken_binary(toy_fmu, tmp_path):
    broken = tmp_path / "broken.fmu"
    with zipfile.ZipFile(toy_fmu) as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            dst.writestr(item, b"not a library" if item.filename.startswith("binaries/") else data)
    problems = validate_fmu(broken)
    assert len(problems) == 1 and "running the FMU failed" in problems[0]


def test_archive_layout(toy_fmu):
    md = read_model_description(str(toy_fmu))
    ident = md.coSimulation.modelIdentifier
    with zipfile.ZipFile(toy_fmu) as zf:
        names = set(zf.namelist())
    # the Reference-FMUs' layout: the FMI API, the slave core and the noise generator beside
    # the model's generated code and config.h (no network code without a network)
    assert names == {"modelDescription.xml", f"binaries/{fmpy.platform}/{ident}.so",
                     "sources/fmi2Functions.c", "sources/wrapper.c", "sources/wrapper.h",
                     "sources/rng.c", "sources/rng.h", "sources/model.c", "sources/model.h",
                     "sources/config.h", "sources/fmi2Functions.h",
                     "sources/fmi2FunctionTypes.h", "sources/fmi2TypesPlatform.h"}
    source_files = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert source_files == ["fmi2Functions.c", "wrapper.c", "rng.c", "model.c"]
    cs = md.coSimulation
    assert cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    assert cs.canHandleVariableCommunicationStepSize == (ident == "duffing")


def test_binary_exports_only_fmi2_functions(toy_fmu, tmp_path):
    """Model code stays private, so FMUs built from same-named systems can share a process."""
    with zipfile.ZipFile(toy_fmu) as zf:
        library = next(n for n in zf.namelist() if n.startswith("binaries/"))
        zf.extract(library, tmp_path)
    nm = subprocess.run(["nm", "-D", "--defined-only", str(tmp_path / library)],
                        capture_output=True, text=True, check=True).stdout
    symbols = {line.split()[-1] for line in nm.splitlines()}
    assert symbols == set(FMI2_CS_FUNCTIONS)


def test_model_description_of_duffing(tmp_path_factory):
    md = read_model_description(str(build_toy(duffing(), tmp_path_factory)))
    v = {x.name: x for x in md.modelVariables}
    assert [u.name for u in md.unitDefinitions] == sorted(
        ["N", "N.s/m", "N/m", "N/m3", "kg", "m", "m/s", "m/s2", "s"])
    assert (v["k"].causality, v["k"].variability, v["k"].start, v["k"].unit) == \
        ("parameter", "tunable", "200.0", "N/m")
    assert [v[n].causality for n in ("F", "q", "q_meas")] == ["input", "local", "output"]
    assert (v["max_substep"].start, v["max_substep"].unit) == ("0.00025", "s")
    assert (v["seed"].type, v["seed"].variability, v["seed"].start) == ("Integer", "fixed", "0")
    deps = {o.variable.name: [d.name for d in o.dependencies] for o in md.outputs}
    assert deps == {"q_meas": [], "q_true": [], "v_true": [], "a": ["F"]}  # feedthrough of F to a
    assert list(md.logCategories) and float(md.defaultExperiment.stepSize) == 1e-3


def test_rebuild_from_sources(toy_fmu, tmp_path):
    """The sources/ folder alone rebuilds a binary that computes exactly the same numbers."""
    md = read_model_description(str(toy_fmu))
    with zipfile.ZipFile(toy_fmu) as zf:
        zf.extractall(tmp_path / "unzipped")
    src = tmp_path / "unzipped" / "sources"
    files = [str(src / f) for f in md.buildConfigurations[0].sourceFileSets[0].sourceFiles]
    library = f"binaries/{fmpy.platform}/{md.coSimulation.modelIdentifier}.so"
    subprocess.run(["gcc", "-shared", "-fPIC", f"-I{src}", *files, "-o",
                    str(tmp_path / "unzipped" / library), "-lm"], check=True)
    rebuilt = tmp_path / "rebuilt.fmu"
    with zipfile.ZipFile(toy_fmu) as zin, zipfile.ZipFile(rebuilt, "w") as zout:
        for name in zin.namelist():
            zout.write(tmp_path / "unzipped" / name, name)
    inputs = {v.name: 0.1 for v in md.modelVariables if v.causality == "input"}
    a, b = (run_fmu(f, 100, inputs=inputs, parameters={"seed": 3}) for f in (toy_fmu, rebuilt))
    assert all(np.array_equal(a[n], b[n]) for n in a)


def test_codegen_and_key_are_deterministic():
    """Two fresh processes generate the same C and the same cache key."""
    script = ("from tests.fmu_toys import duffing; from flexff.fmu import fmu_key; "
              "from flexff.fmu.codegen import generate_model_c; import hashlib; "
              "print(fmu_key(duffing()), hashlib.sha256(str(generate_model_c(duffing(), 'd'))"
              ".encode()).hexdigest())")
    outputs = {subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              check=True, cwd=REPOSITORY).stdout for _ in range(2)}
    assert len(outputs) == 1
    key, _ = outputs.pop().split()
    assert key == fmu_key(duffing())


def test_cache_hit_is_fast_and_identical(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))
    start = time.perf_counter()
    first = build_fmu(duffing(name="cached"), tmp_path / "a.fmu")
    miss = time.perf_counter() - start
    start = time.perf_counter()
    second = build_fmu(duffing(name="cached"), tmp_path / "b.fmu")
    hit = time.perf_counter() - start
    assert first.read_bytes() == second.read_bytes()
    cached = [p.name for p in (tmp_path / "cache").iterdir()]
    assert cached == [f"{fmu_key(duffing(name='cached'))}.fmu"]
    assert hit < miss / 3, (hit, miss)


def test_changes_change_the_key():
    keys = {fmu_key(s) for s in [duffing(), duffing(k=201.0), duffing(max_substep=1e-4),
                                 duffing(name="other"), discrete_pi(),
                                 discrete_pi(sample_time=2e-3)]}
    assert len(keys) == 6


def test_a_sanitizer_build_has_its_own_key(monkeypatch):
    """$FLEXFF_SANITIZE adds the sanitizer's flags (tests/fmu/test_fuzz.py builds with it);
    such a build never replaces the plain one in the cache."""
    plain = fmu_key(duffing())
    monkeypatch.setenv(SANITIZE_ENV, "address,undefined")
    assert sanitizer_flags() == ("-fsanitize=address,undefined", "-fno-omit-frame-pointer", "-g")
    assert fmu_key(duffing()) != plain
    monkeypatch.setenv(SANITIZE_ENV, "address; rm -rf /")
    with pytest.raises(ValueError, match="FLEXFF_SANITIZE"):
        sanitizer_flags()
    monkeypatch.setenv(SANITIZE_ENV, "")
    assert sanitizer_flags() == () and fmu_key(duffing()) == plain


def test_guid_follows_the_key(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))
    guids = {read_model_description(str(build_fmu(s, tmp_path / f"{i}.fmu"))).guid
             for i, s in enumerate([duffing(), duffing(), duffing(c=1.0)])}
    assert len(guids) == 2


def test_sparse_and_mx_functions(tmp_path_factory):
    """MX functions and structurally sparse results (a zero row) give the same numbers."""
    base = duffing()
    syms = [ca.MX.sym(f"a{i}", n) for i, n in enumerate((2, 1, 7, 1))]
    output = ca.Function("h", syms, [ca.vertcat(base.output(*syms), ca.MX(1, 1))])
    mx = type(base)(**{
        **base.__dict__, "name": "duffing_mx", "output": output,
        "outputs": (*base.outputs, Variable("zero")),
        "dynamics": ca.Function("f", syms[:3], [base.dynamics(*syms[:3])]),
        "initial_state": ca.Function("x0", syms[2:3], [base.initial_state(syms[2])]),
    })
    assert mx.dynamics.is_a("MXFunction") and output.sparsity_out(0).nnz() < 5
    runs = [run_fmu(build_toy(s, tmp_path_factory), 200, inputs={"F": 1.0}, parameters={"seed": 2})
            for s in (base, mx)]
    assert all(np.abs(runs[0][n] - runs[1][n]).max() <= 1e-15 for n in runs[0])
    assert np.array_equal(runs[1]["zero"], np.zeros(201))


def test_minimal_systems(tmp_path_factory):
    """No inputs, no parameters, no noise; and even no outputs at all."""
    x, none = ca.SX.sym("x"), ca.SX.sym("none", 0)
    decay = System("decay", "x' = -x", "continuous", (Variable("x"),), (), (Variable("y"),), (),
                   ca.Function("i", [none], [ca.DM(1.0)]), ca.Function("f", [x, none, none], [-x]),
                   ca.Function("h", [x, none, none, none], [2 * x]))
    silent = type(decay)(**{**decay.__dict__, "name": "silent", "outputs": (),
                            "output": ca.Function("h", [x, none, none, none], [ca.SX(0, 1)])})
    for system in (decay, silent):
        path = build_toy(system, tmp_path_factory)
        assert validate_fmu(path) == []
        run = run_fmu(path, 1000, record=["x"])
        assert run["x"][-1] == pytest.approx(np.exp(-1.0), rel=1e-12)


@pytest.mark.parametrize("change, message", [
    ({"outputs": (Variable("I"),)}, "duplicated: ['I']"),
    ({"outputs": (Variable("seed"),)}, "duplicated: ['seed']"),
    ({"kind": "hybrid"}, "kind must be"),
    ({"sample_time": None}, "positive sample_time"),
])
def test_bad_systems_are_rejected(change, message):
    base = discrete_pi()
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        make_layout(type(base)(**{**base.__dict__, **change}))


def test_wrong_function_shapes_are_rejected():
    base = duffing()
    x = ca.SX.sym("x", 3)
    with pytest.raises(ValueError, match="argument 0 of dynamics must be a dense column of len"):
        generate_model_c(type(base)(**{**base.__dict__, "dynamics": ca.Function(
            "f", [x, ca.SX.sym("u"), ca.SX.sym("p", 7)], [x])}), "d")
