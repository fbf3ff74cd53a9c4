"""The generic C wrapper's FMI 2.0 behaviour: state machine, checks, FMU states, logging.

Every misuse must return the documented status, log a message naming the culprit, and leave
the process (and, where documented, the instance) in a usable state.
"""

import struct
import time
from ctypes import (
    addressof,
    byref,
    c_char,
    c_double,
    c_size_t,
    c_uint,
    c_void_p,
    create_string_buffer,
)

import numpy as np
import pytest
from fmpy.fmi2 import (
    fmi2CoSimulation,
    fmi2Discard,
    fmi2DoStepStatus,
    fmi2Error,
    fmi2FMUstate,
    fmi2LastSuccessfulTime,
    fmi2ModelExchange,
    fmi2OK,
    fmi2PendingStatus,
    fmi2Terminated,
)

from tests.fmu_toys import LoggedSlave, status_of

H = 1e-3


@pytest.fixture
def slave(duffing_fmu):
    s = LoggedSlave(duffing_fmu)
    yield s
    s.free()


def run(s: LoggedSlave, steps: int, start: int = 0, names=("q_meas", "q", "v", "a")) -> np.ndarray:
    """Step with a known force sequence from step `start`, reading `names` after each step."""
    out = []
    for k in range(start, start + steps):
        s.set(F=np.sin(0.05 * k))
        s.slave.doStep(k * H, H)
        out.append(s.get(*names))
    return np.array(out)


# --- state machine --------------------------------------------------------------------------

def test_calls_out_of_order_are_errors(slave):
    f, c = slave.slave, slave.slave.component
    assert status_of(f.fmi2DoStep, c, 0.0, H, 1) == fmi2Error
    assert "fmi2DoStep() is not allowed in state 'instantiated'" in slave.log()
    assert status_of(f.fmi2ExitInitializationMode, c) == fmi2Error
    assert status_of(f.fmi2Terminate, c) == fmi2Error
    assert status_of(lambda: f.getReal([slave.vr["q"]])) == fmi2Error
    slave.initialize()
    assert status_of(f.fmi2EnterInitializationMode, c) == fmi2Error
    assert status_of(f.fmi2SetupExperiment, c, 0, 0.0, 0.0, 0, 0.0) == fmi2Error
    assert "fmi2SetupExperiment() is not allowed in state 'stepping" in slave.log()
    run(slave, 3)
    assert f.terminate() == fmi2OK
    assert status_of(lambda: slave.set(F=1.0)) == fmi2Error
    assert "fmi2SetReal() is not allowed in state 'terminated'" in slave.log()
    assert status_of(f.fmi2DoStep, c, 3 * H, H, 1) == fmi2Error
    assert len(slave.get("q", "v")) == 2  # reading a terminated instance is allowed
    assert status_of(f.fmi2Reset, c) == fmi2OK
    slave.initialize()
    assert run(slave, 2).shape == (2, 4)


def test_null_pointers_are_errors(slave):
    f, c = slave.slave, slave.slave.component
    for call, args in [(f.fmi2DoStep, (0.0, H, 1)), (f.fmi2EnterInitializationMode, ()),
                       (f.fmi2GetFMUstate, (byref(fmi2FMUstate()),)), (f.fmi2Reset, ()),
                       (f.fmi2GetReal, (None, 0, None))]:
        assert status_of(call, None, *args) == fmi2Error  # no instance at all
    f.fmi2FreeInstance(None)  # must not crash
    slave.initialize()
    assert status_of(f.fmi2GetReal, c, None, 2, None) == fmi2Error
    assert "null value reference or value array" in slave.log()
    assert status_of(f.fmi2GetReal, c, None, 0, None) == fmi2OK  # nothing to read
    assert status_of(f.fmi2GetFMUstate, c, None) == fmi2Error
    assert status_of(f.fmi2SetFMUstate, c, None) == fmi2Error
    assert status_of(f.fmi2SerializedFMUstateSize, c, None, None) == fmi2Error
    assert "invalid FMU state" in slave.log()
    assert status_of(f.fmi2GetRealStatus, c, fmi2LastSuccessfulTime, None) == fmi2Error
    assert status_of(f.fmi2SetDebugLogging, c, 1, 2, None) == fmi2Error


def test_freed_and_garbage_component_pointers_are_errors(duffing_fmu):
    """Live instances are registered: a second fmi2FreeInstance, a call after it and a pointer
    to anything else are refused without reading the memory behind them (they read freed
    memory before, or crashed)."""
    s = LoggedSlave(duffing_fmu)
    f, freed = s.slave, s.slave.component
    s.initialize()
    f.fmi2FreeInstance(freed)
    f.fmi2FreeInstance(freed)  # the second free is a no-op
    garbage = create_string_buffer(b"FLXF" * 64)  # even with the magic number in it
    for comp in (freed, c_void_p(addressof(garbage)), c_void_p(0x10)):
        assert status_of(f.fmi2DoStep, comp, 0.0, H, 1) == fmi2Error
        assert status_of(f.fmi2Reset, comp) == fmi2Error
        assert status_of(f.fmi2GetFMUstate, comp, byref(fmi2FMUstate())) == fmi2Error
        f.fmi2FreeInstance(comp)
    other = LoggedSlave(duffing_fmu, unzipdir=s.unzipdir)  # the library still works
    other.initialize()
    assert np.isfinite(run(other, 2)).all()
    other.slave.freeInstance()
    s.free()  # frees the freed instance a third time, then unloads the library


def test_instances_beyond_the_registry_are_refused(duffing_fmu):
    s = LoggedSlave(duffing_fmu)
    f, cb = s.slave, byref(s.callbacks)
    made = []
    while len(made) < 5000:
        comp = f.fmi2Instantiate(b"many", fmi2CoSimulation, s.guid.encode(), b"", cb, 0, 0)
        if comp is None:
            break
        made.append(comp)
    assert len(made) == 4096 - 1  # with `s`, the most instances one library holds
    assert "4096 instances of this FMU are alive in this process" in s.log()
    for comp in made:
        f.fmi2FreeInstance(comp)
    assert f.fmi2Instantiate(b"again", fmi2CoSimulation, s.guid.encode(), b"", cb, 0, 0)
    s.free()


def test_instantiate_checks_its_arguments(slave):
    f = slave.slave
    cb = byref(slave.callbacks)
    assert f.fmi2Instantiate(b"x", fmi2CoSimulation, b"{wrong}", b"", cb, 0, 0) is None
    assert "GUID '{wrong}' does not match" in slave.log()
    assert f.fmi2Instantiate(b"x", fmi2ModelExchange, slave.guid.encode(), b"", cb, 0, 0) is None
    assert "co-simulation only" in slave.log()
    assert f.fmi2Instantiate(b"", fmi2CoSimulation, slave.guid.encode(), b"", cb, 0, 0) is None
    assert f.fmi2Instantiate(b"x", fmi2CoSimulation, slave.guid.encode(), b"", None, 0, 0) is None


def test_wrong_communication_point_and_step(slave):
    slave.initialize()
    f, c = slave.slave, slave.slave.component
    assert status_of(f.fmi2DoStep, c, 0.5, H, 1) == fmi2Error
    assert "currentCommunicationPoint = 0.5 but the FMU is at time 0" in slave.log()
    assert status_of(f.fmi2DoStep, c, 0.0, -H, 1) == fmi2Error
    assert status_of(f.fmi2DoStep, c, 0.0, float("nan"), 1) == fmi2Error
    assert run(slave, 2).shape == (2, 4)  # the instance is still usable


def test_a_step_of_too_many_sub_steps_is_refused_at_once(slave):
    """A huge step with a tiny max_substep is refused before it starts (it could run for
    10^9 sub-steps), naming both; the instance stays usable."""
    slave.initialize()
    slave.set(max_substep=1e-9)
    start = time.perf_counter()
    assert status_of(slave.slave.fmi2DoStep, slave.slave.component, 0.0, 10.0, 1) == fmi2Error
    assert time.perf_counter() - start < 0.5
    assert ("communicationStepSize = 10 s needs 1e+10 RK4 sub-steps of max_substep = 1e-09 s, "
            "more than the 1000000 allowed per step") in slave.log()
    slave.set(max_substep=2.5e-4)
    assert np.isfinite(run(slave, 2)).all()


def test_stop_time_is_enforced(slave):
    slave.slave.setupExperiment(startTime=0.0, stopTime=2 * H)
    slave.slave.enterInitializationMode()
    slave.slave.exitInitializationMode()
    run(slave, 2)
    assert status_of(slave.slave.fmi2DoStep, slave.slave.component, 2 * H, H, 1) == fmi2Error
    assert "passes stopTime" in slave.log()


# --- variable access ------------------------------------------------------------------------

def test_nan_input_is_rejected_and_not_applied(slave):
    slave.initialize()
    slave.set(F=1.5)
    for bad in (float("nan"), float("inf")):
        assert status_of(slave.set, F=bad) == fmi2Error
        assert "input 'F' =" in slave.log() and "is not finite" in slave.log()
    assert slave.get("F") == [1.5]
    assert np.isfinite(run(slave, 3)).all()


def test_bad_parameters_rejected_at_initialization(slave):
    f = slave.slave
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    for name, value in [("m", -1.0), ("k", 0.0), ("alpha", float("nan")), ("max_substep", 0.0)]:
        good = slave.get(name)[0]
        slave.set(**{name: value})  # accepted for now: checked when initialization ends
        assert status_of(f.fmi2ExitInitializationMode, f.component) == fmi2Error
        assert f"Parameter '{name}' = " in slave.messages[-1][2]
        slave.set(**{name: good})  # still in initialization mode: fix it and retry
    slave.set(alpha=-10.0)  # not declared positive: a softening spring is fine
    f.exitInitializationMode()
    assert np.isfinite(run(slave, 2)).all()


def test_bad_parameters_rejected_while_stepping(slave):
    slave.initialize()
    run(slave, 2)
    for name, value in [("k", 0.0), ("c", -0.1), ("sigma", float("inf")), ("max_substep", -1e-3)]:
        before = slave.get(name)
        assert status_of(slave.set, **{name: value}) == fmi2Error
        assert f"parameter '{name}' = " in slave.messages[-1][2]
        assert slave.get(name) == before
    slave.set(k=300.0, max_substep=1e-4)  # good values are taken
    assert slave.get("k", "max_substep") == [300.0, 1e-4]


def test_only_parameters_and_inputs_can_be_set(slave):
    slave.initialize()
    assert status_of(lambda: slave.set(q_meas=1.0)) == fmi2Error
    assert "'q_meas' is an output and cannot be set" in slave.log()
    assert status_of(lambda: slave.set(q=1.0)) == fmi2Error
    assert "'q' is an internal state and cannot be set" in slave.log()
    f, c = slave.slave, slave.slave.component
    assert status_of(f.fmi2SetReal, c, (c_uint * 1)(999), 1, (c_double * 1)(0.0)) == fmi2Error
    assert "unknown value reference 999" in slave.log()
    # a call with one bad value changes nothing, not even the good values before it
    assert status_of(lambda: f.setReal([slave.vr["F"], slave.vr["q"]], [2.0, 0.0])) == fmi2Error
    assert slave.get("F") == [0.0]


def test_integer_boolean_string_access(slave):
    f = slave.slave
    f.setupExperiment()
    f.enterInitializationMode()
    f.setInteger([slave.vr["seed"]], [42])
    f.exitInitializationMode()
    assert f.getInteger([slave.vr["seed"]]) == [42]
    assert status_of(lambda: f.setInteger([slave.vr["seed"]], [1])) == fmi2Error
    assert "'seed' is fixed after initialization" in slave.log()
    assert status_of(lambda: f.getInteger([0])) == fmi2Error
    assert f.getBoolean([]) == [] and f.getString([]) == []
    assert status_of(lambda: f.getBoolean([0])) == fmi2Error
    assert status_of(lambda: f.setString([0], ["x"])) == fmi2Error
    assert "no String variables" in slave.log()


def test_discrete_step_must_equal_sample_time(pi_fmu):
    s = LoggedSlave(pi_fmu)
    s.initialize()
    s.set(r=1.0)
    s.slave.doStep(0.0, 1e-3)
    assert status_of(s.slave.fmi2DoStep, s.slave.component, 1e-3, 2e-3, 1) == fmi2Error
    assert "differs from the sample time 0.001" in s.log()
    s.slave.doStep(1e-3, 1e-3 * (1 + 1e-12))  # within the relative 1e-9 tolerance
    assert s.get("I") == [2e-3]
    s.free()


def test_non_finite_state_after_step(slave):
    slave.initialize(alpha=1e15, q0=0.5)  # absurdly stiff spring: RK4 blows up
    f, c = slave.slave, slave.slave.component
    statuses = []
    for k in range(100):
        statuses.append(status_of(f.fmi2DoStep, c, k * H, H, 1))
        if statuses[-1] != fmi2OK:
            break
    assert statuses[-1] == fmi2Error
    assert "became" in slave.log() and ("state 'q'" in slave.log() or "state 'v'" in slave.log())
    assert np.isfinite(slave.get("q", "v")).all()  # the last good state is kept
    assert status_of(f.fmi2DoStep, c, k * H, H, 1) == fmi2Error
    assert "not allowed in state 'error'" in slave.log()
    f.reset()
    slave.initialize()
    assert np.isfinite(run(slave, 3)).all()


# --- FMU states -----------------------------------------------------------------------------

def test_fmu_state_round_trip_is_exact(slave):
    slave.initialize(seed=5)
    run(slave, 50)
    f = slave.slave
    saved = f.getFMUstate()
    blob = f.serializeFMUstate(saved)
    reference = run(slave, 100, start=50)
    f.setFMUstate(saved)
    assert np.array_equal(run(slave, 100, start=50), reference)
    restored = f.deSerializeFMUstate(blob)
    f.setFMUstate(restored)
    assert np.array_equal(run(slave, 100, start=50), reference)
    f.getFMUstate()  # reuse of an existing state object
    f.fmi2GetFMUstate(f.component, byref(saved))
    f.freeFMUstate(saved)
    f.freeFMUstate(restored)
    assert saved.value is None and restored.value is None


def test_serialized_state_moves_between_instances(duffing_fmu, slave):
    slave.initialize(seed=3, k=150.0)
    run(slave, 30)
    blob = slave.slave.serializeFMUstate(slave.slave.getFMUstate())
    reference = run(slave, 40, start=30)
    other = LoggedSlave(duffing_fmu, instance_name="other")
    other.slave.setFMUstate(other.slave.deSerializeFMUstate(blob))  # even from 'instantiated'
    assert np.array_equal(run(other, 40, start=30), reference)
    other.free()


def test_deserialize_validates_the_blob(slave, pi_fmu):
    slave.initialize()
    f = slave.slave
    blob = f.serializeFMUstate(f.getFMUstate())

    def status(data: bytes) -> int:
        buffer = (c_char * len(data)).from_buffer_copy(data)
        return status_of(f.fmi2DeSerializeFMUstate, f.component, buffer, len(data),
                         byref(fmi2FMUstate()))

    assert status(blob[:-1]) == fmi2Error
    assert status(b"X" + blob[1:]) == fmi2Error
    assert "not a serialized state" in slave.log()
    assert status(blob[:16] + bytes([blob[16] ^ 1]) + blob[17:]) == fmi2Error
    assert "belongs to another model" in slave.log()
    pi = LoggedSlave(pi_fmu)
    pi.initialize()
    assert status(pi.slave.serializeFMUstate(pi.slave.getFMUstate())) == fmi2Error
    pi.free()


def test_a_state_of_another_model_is_refused(slave, pi_fmu):
    """An FMU state of another flexff FMU in the process holds another model's data, of
    another size: restoring or serializing it read past its end."""
    slave.initialize()
    pi = LoggedSlave(pi_fmu)
    pi.initialize()
    foreign = pi.slave.getFMUstate()
    f, c = slave.slave, slave.slave.component
    assert status_of(f.fmi2SetFMUstate, c, foreign) == fmi2Error
    assert "the FMU state belongs to another model" in slave.log()
    assert status_of(f.fmi2SerializedFMUstateSize, c, foreign, byref(c_size_t())) == fmi2Error
    assert status_of(f.fmi2FreeFMUstate, c, byref(foreign)) == fmi2Error
    assert status_of(f.fmi2GetFMUstate, c, byref(foreign)) == fmi2Error  # not overwritten
    pi.slave.setFMUstate(foreign)  # still the other model's, intact
    pi.slave.freeFMUstate(foreign)
    pi.free()


def _offset(blob: bytes, value: float) -> int:
    """Where the double `value` is stored in a serialized state (after the 24-byte header)."""
    [offset] = [k for k in range(24, len(blob) - 7, 8) if struct.unpack_from("<d", blob, k)[0]
                == value]
    return offset


def test_deserialize_checks_every_field(slave):
    """A serialized state comes from outside: each field is checked against what the FMU can
    produce itself, and a corrupt one is refused, naming it."""
    slave.initialize(k=123.456)
    slave.set(F=0.777)
    run(slave, 3)
    slave.set(F=0.777)
    f = slave.slave
    blob = f.serializeFMUstate(f.getFMUstate())
    [q] = slave.get("q")

    def status(offset: int, fmt: str, value) -> int:
        data = blob[:offset] + struct.pack(fmt, value) + blob[offset + struct.calcsize(fmt):]
        buffer = (c_char * len(data)).from_buffer_copy(data)
        return status_of(f.fmi2DeSerializeFMUstate, f.component, buffer, len(data),
                         byref(fmi2FMUstate()))

    nan, inf = float("nan"), float("inf")
    for offset, fmt, value, message in [
            (24, "<i", 3, "machine state 3 is none of the FMU's"),
            (_offset(blob, 3 * H), "<d", nan, "time = nan"),
            (_offset(blob, 123.456), "<d", -1.0, "parameter 'k' = -1 must be > 0"),
            (_offset(blob, 0.777), "<d", inf, "input 'F' = inf"),
            (_offset(blob, q), "<d", nan, "state 'q' = nan")]:
        assert status(offset, fmt, value) == fmi2Error
        assert slave.messages[-1][2] == f"fmi2DeSerializeFMUstate(): corrupt state: {message}."
    restored = f.deSerializeFMUstate(blob)  # the intact blob restores
    f.setFMUstate(restored)
    assert slave.get("q") == [q]
    f.freeFMUstate(restored)


def test_two_instances_are_independent(duffing_fmu):
    """Two instances of one loaded library, interleaved, equal two runs one after the other."""
    a = LoggedSlave(duffing_fmu, instance_name="a")
    b = LoggedSlave(duffing_fmu, instance_name="b", unzipdir=a.unzipdir)
    a.initialize(seed=1)
    b.initialize(seed=2, k=300.0)
    ra, rb = [], []
    for k in range(50):
        ra.append(run(a, 1, start=k)[0])
        rb.append(run(b, 1, start=k)[0])
    for s, params, out in ((a, {"seed": 1}, ra), (b, {"seed": 2, "k": 300.0}, rb)):
        s.slave.reset()
        s.initialize(**params)
        assert np.array_equal(run(s, 50), np.array(out))
    assert not np.array_equal(np.array(ra), np.array(rb))
    a.free()
    b.free()


def test_reset_restores_start_values(slave):
    slave.initialize(k=500.0, seed=9)
    first = run(slave, 20)
    slave.slave.reset()
    assert status_of(lambda: slave.get("q")) == fmi2Error  # back to 'instantiated'
    slave.initialize()
    assert slave.get("k") == [200.0] and slave.slave.getInteger([slave.vr["seed"]]) == [0]
    slave.slave.reset()
    slave.initialize(k=500.0, seed=9)
    assert np.array_equal(run(slave, 20), first)


# --- logging and unsupported features -------------------------------------------------------

def test_logging_categories(duffing_fmu):
    s = LoggedSlave(duffing_fmu, logging_on=True)
    s.initialize()
    assert ("logAll", "fmi2ExitInitializationMode()") in [(c, m) for _, c, m in s.messages]
    s.slave.setDebugLogging(False, ["logAll", "logStatusError"])
    s.messages.clear()
    assert status_of(lambda: s.set(F=float("nan"))) == fmi2Error
    run(s, 2)
    assert s.messages == []
    assert status_of(lambda: s.slave.setDebugLogging(True, ["noSuchCategory"])) == fmi2Error
    s.slave.setDebugLogging(True, [])  # no categories: all of them
    assert status_of(lambda: s.set(F=float("nan"))) == fmi2Error
    assert [c for _, c, _ in s.messages] == ["logAll", "logStatusError"]
    s.free()


def test_unsupported_calls_report_status(slave):
    slave.initialize()
    run(slave, 3)
    f = slave.slave
    assert f.getRealStatus(fmi2LastSuccessfulTime) == pytest.approx(3 * H, abs=1e-15)
    assert f.getBooleanStatus(fmi2Terminated) is False
    assert status_of(lambda: f.getStatus(fmi2DoStepStatus)) == fmi2Discard
    assert status_of(lambda: f.getIntegerStatus(fmi2PendingStatus)) == fmi2Discard
    assert status_of(lambda: f.getStringStatus(fmi2PendingStatus)) == fmi2Discard
    assert status_of(lambda: f.getRealStatus(fmi2DoStepStatus)) == fmi2Discard
    assert status_of(f.cancelStep) == fmi2Error
    assert status_of(lambda: f.setRealInputDerivatives([slave.vr["F"]], [1], [0.0])) == fmi2Error
    assert status_of(lambda: f.getRealOutputDerivatives([slave.vr["q_meas"]], [1])) == fmi2Error
    assert status_of(lambda: f.getDirectionalDerivative([slave.vr["a"]], [slave.vr["F"]], [1.0])) \
        == fmi2Error
    assert f.getTypesPlatform() == "default" and f.getVersion() == "2.0"
    assert np.isfinite(run(slave, 2, start=3)).all()
