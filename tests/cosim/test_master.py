"""The master against the monolithic closed loop (tests/loops.py), the C floor, and its
load-time and run-time errors."""

import numpy as np
import pytest

from flexff.cosim.floor import run_c_loop
from flexff.cosim.master import CosimError, Master, ResolvedFmu
from flexff.cosim.recording import chunk_rows
from flexff.cosim.scenario import reference_samples
from flexff.cosim.wiring import SOURCE, Port, wire
from flexff.fmu.importer import read_fmu
from flexff.plant.references import thesis_evaluation
from tests.helpers import REFERENCE_FMUS
from tests.loops import STEP, loop_systems, monolithic

STOP = 15.0
STEPS = round(STOP / STEP)
MAX_SUBSTEP = 2.5e-4  # four RK4 sub-steps per communication step


@pytest.fixture(scope="module")
def systems():
    return loop_systems("nominal")


@pytest.fixture(scope="module")
def fmus(loop_fmus):
    return loop_fmus("nominal")


@pytest.fixture(scope="module")
def reference():
    return reference_samples(thesis_evaluation(STEP), STEPS)


def resolved(fmus, plant_parameters=None):
    return [ResolvedFmu("feedforward", fmus["feedforward"]),
            ResolvedFmu("controller", fmus["controller"]),
            ResolvedFmu("plant", fmus["plant"], plant_parameters or {})]


def test_closed_loop_equals_the_monolithic_simulation(systems, fmus, reference):
    points = {n: v[:STEPS + 1] for n, v in reference.items()}
    expected = monolithic(systems, points, MAX_SUBSTEP)
    with Master(resolved(fmus, {"max_substep": MAX_SUBSTEP}), list(reference), STEP) as master:
        rec = master.run(reference, STEPS)
    for name, values in expected.items():
        assert np.abs(rec[name] - values).max() <= 1e-9, name
    assert np.ptp(rec["x"]) > 0.02  # it really followed the 28 mm circle
    assert rec.time[-1] == pytest.approx(STOP) and rec.time.size == STEPS + 1


def test_the_c_loop_records_the_same_numbers(fmus, reference):
    sources = {n: v[:2001] for n, v in reference.items()}
    with Master(resolved(fmus), list(sources), STEP) as master:
        c_record, us_per_step = run_c_loop(master, sources, 2000, repeats=1)
        rec = master.run(sources, 2000)
    assert us_per_step > 0
    for name in rec.signals:
        assert np.array_equal(c_record[name], rec[name]), name


def test_connections_by_name(fmus):
    ports = [Port(name, read_fmu(fmus[name])) for name in ("feedforward", "controller", "plant")]
    sources = ["x_ref", "y_ref", "vx_ref", "vy_ref", "ax_ref", "ay_ref"]
    by_input = {(c.consumer, c.input): c for c in wire(ports, sources)}
    assert by_input["controller", "Fx_ff"].producer == "feedforward"
    assert not by_input["controller", "Fx_ff"].feedback
    assert by_input["controller", "theta_s1"].producer == "plant"
    assert by_input["controller", "theta_s1"].feedback
    assert by_input["feedforward", "x_ref"].producer == SOURCE
    with pytest.raises(ValueError, match="input 'Fx_ff' is not connected"):
        wire(ports[1:], sources)
    with pytest.raises(ValueError, match="algebraic loop"):  # the currents come back
        wire([ports[2], ports[1]], [*sources, "Fx_ff", "Fy_ff"])
    with pytest.raises(ValueError, match=r"'theta_s1' matches theta_s1 and plant.theta_s1"):
        wire(ports, [*sources, "theta_s1"])


def test_an_unconnected_input_fails_at_load_time(fmus):
    with pytest.raises(ValueError, match="input 'Fx_ff' is not connected"):
        Master([ResolvedFmu("controller", fmus["controller"]), ResolvedFmu("plant", fmus["plant"])],
               ["x_ref", "y_ref"], STEP)


def test_unknown_parameter_fails_at_load_time(fmus):
    with pytest.raises(ValueError, match="plant: unknown parameter 'm_upper'"):
        Master(resolved(fmus, {"m_upper": 0.3}), ["x_ref", "y_ref"], STEP)


def test_a_failing_fmu_call_carries_the_fmu_message(fmus, reference):
    with Master(resolved(fmus, {"k_t1": -1.0}), list(reference), STEP) as master:
        with pytest.raises(CosimError, match=r"plant: fmi2ExitInitializationMode failed: "
                                             r"\[Error\] Parameter 'k_t1' = -1 must be > 0"):
            master.run(reference, STEPS)


def test_recording_a_selection(fmus, reference):
    sources = {n: v[:101] for n, v in reference.items()}
    with Master(resolved(fmus), list(sources), STEP) as master:
        rec = master.run(sources, 100, record=["y", "x_ref", "i2"])
    assert list(rec.signals) == ["y", "x_ref", "i2"]
    assert np.array_equal(rec["x_ref"], sources["x_ref"])
    with Master(resolved(fmus), list(sources), STEP) as master:
        with pytest.raises(ValueError, match="cannot record unknown signal"):
            master.run(sources, 100, record=["z"])


def test_each_fmu_keeps_its_own_messages(fmus):
    """The failing plant is instantiated first: its message must not go to the controller."""
    sources = {"x_ref": 0.0, "y_ref": 0.0, "Fx_ff": 0.0, "Fy_ff": 0.0}
    with Master([ResolvedFmu("plant", fmus["plant"], {"k_t1": -1.0}),
                 ResolvedFmu("controller", fmus["controller"])], list(sources), STEP,
                algorithm="jacobi") as master:
        with pytest.raises(CosimError, match=r"^plant: .*Parameter 'k_t1' = -1 must be > 0"):
            master.run(sources, 10)


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_array_sources_over_several_chunks_reach_the_fmu_unchanged(rng, algorithm):
    """A run of three chunks with two array sources and a constant fed to the Reference-FMU
    Feedthrough: the recorded sources are the arrays fed in, bit for bit, the FMU's output
    follows its input (a step late under Jacobi), and the master holds a chunk of source
    rows, not the run's."""
    path = REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu"
    steps, info = 250_000, read_fmu(path)
    sources = {"Float64_continuous_input": rng.standard_normal(steps + 1),
               "Float64_discrete_input": rng.standard_normal(steps + 1),
               "Float64_tunable_parameter": 0.25}
    links = wire([Port("ft", info, "start")], list(sources), algorithm=algorithm)
    record = [*sources, "ft.Float64_continuous_output"]
    rows = chunk_rows(1 + len(record))
    assert steps + 1 > 2 * rows
    with Master([ResolvedFmu("ft", path, info=info)], list(sources), 1e-3, links,
                algorithm) as master:
        rec = master.run(sources, steps, record)
        source_rows = master._arrays[0]
    assert source_rows.shape == (rows, 3)
    for name in ("Float64_continuous_input", "Float64_discrete_input"):
        assert rec[name].tobytes() == sources[name].tobytes(), name
    assert np.all(rec["Float64_tunable_parameter"] == 0.25)
    fed, out = sources["Float64_continuous_input"], rec["ft.Float64_continuous_output"]
    if algorithm == "gauss-seidel":
        assert np.array_equal(out, fed)
    else:
        assert np.array_equal(out[1:], fed[:-1])
