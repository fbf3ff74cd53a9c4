"""The same FMUs under a second importer, libcosim (through libcosimpy), give fmpy's numbers.

libcosim parses modelDescription.xml with the FMI Library, drives the FMU through its own
master (integer-nanosecond clock) and reads values through observers: agreement to 1e-12 shows
the FMU does not depend on fmpy's particular call sequence.
"""

import numpy as np
import pytest

from tests.fmu_toys import LoggedSlave, build_toy, discrete_pi, duffing
from tests.runners import run_fmu_libcosim

STEPS = 300
H = 1e-3


def run_libcosim(fmu, parameters, seed, inputs, record):
    """libcosim's samples after every step, as a (steps x len(record)) array."""
    parameters = dict(parameters, **({"seed": seed} if seed is not None else {}))
    result = run_fmu_libcosim(fmu, STEPS, H, inputs, parameters, record)
    return np.column_stack([result[n] for n in record])


def run_fmpy(fmu, parameters, seed, inputs, record):
    s = LoggedSlave(fmu)
    s.initialize(seed=seed, **parameters)
    out = []
    for k in range(STEPS):
        s.set(**{n: float(inputs[n][k]) for n in inputs})
        s.slave.doStep(k * H, H)
        out.append(s.get(*record))
    s.free()
    return np.array(out)


@pytest.mark.parametrize("make, parameters, seed, inputs, record", [
    (duffing, {"k": 260.0, "sigma": 0.01, "max_substep": 1e-4}, 11,
     {"F": 3.0 * np.sin(0.02 * np.arange(STEPS))}, ["q_meas", "q_true", "v_true", "a", "q", "v"]),
    (discrete_pi, {"kp": 20.0, "umax": 0.3}, None,
     {"r": np.full(STEPS, 0.01), "y": 0.02 * np.cos(0.05 * np.arange(STEPS))}, ["u", "I"]),
], ids=["duffing", "discrete_pi"])
def test_libcosim_equals_fmpy(tmp_path_factory, make, parameters, seed, inputs, record):
    fmu = build_toy(make(), tmp_path_factory)
    ours = run_fmpy(fmu, parameters, seed, inputs, record)
    theirs = run_libcosim(fmu, parameters, seed, inputs, record)
    assert np.abs(theirs - ours).max() <= 1e-12
    assert np.ptp(ours, axis=0).min() > 0  # every recorded signal moved
