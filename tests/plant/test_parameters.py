"""Parameter values, validation and the variants."""

import math

import numpy as np
import pytest

from flexff.plant.analysis import modes, plant_info
from flexff.plant.model import PlantModel
from flexff.plant.parameters import HARDWARE, NOMINAL, PlantParameters
from flexff.plant.variants import get_variant


def test_seed_figures_are_kept():
    assert NOMINAL.l_up == NOMINAL.l_low == 0.3086
    assert NOMINAL.k_t == (36.9e-3,) * 3
    assert NOMINAL.encoder_counts == 2048
    assert NOMINAL.workspace_radius == 0.05


def test_flat_vector_round_trip_and_names():
    names = PlantParameters.names()
    assert len(names) == len(set(names)) == len(NOMINAL.vector())
    assert {"m_up1", "m_up2", "m_up3", "k_t3", "i_max", "noise_std"} <= set(names)
    assert PlantParameters.from_vector(NOMINAL.vector()) == NOMINAL


@pytest.mark.parametrize("name", ["m_up2", "k_s1", "k_e3", "m_ee", "j_low1", "encoder_counts"])
def test_non_positive_physical_parameters_are_rejected_by_name(name):
    for bad in (0.0, -1.0):
        with pytest.raises(ValueError, match=f"{name} = {bad}.* must be positive"):
            NOMINAL.with_values(**{name: bad})
    with pytest.raises(ValueError, match=f"{name} = nan .*not finite"):
        NOMINAL.with_values(**{name: math.nan})


def test_negative_damping_and_unknown_names_are_rejected():
    with pytest.raises(ValueError, match=r"d_s1 = -0.1 .*must not be negative"):
        NOMINAL.with_values(d_s1=-0.1)
    with pytest.raises(ValueError, match=r"unknown plant parameter\(s\) \['mass'\]"):
        NOMINAL.with_values(mass=1.0)
    with pytest.raises(ValueError, match="reach"):
        NOMINAL.with_values(r_mount=0.7)


def test_unknown_variant_is_named():
    with pytest.raises(ValueError,
                       match="unknown plant variant 'real': choose one of nominal, hardware"):
        get_variant("real")


def test_hardware_differs_from_nominal_in_every_effect():
    assert HARDWARE.m_up != NOMINAL.m_up and HARDWARE.k_s != NOMINAL.k_s
    assert min(HARDWARE.tau_coulomb) > 0 and HARDWARE.noise_std > 0
    assert get_variant("hardware").parasitic_mode and not get_variant("nominal").parasitic_mode


def test_lowest_mode_at_the_centre_is_1_7_hz_and_lightly_damped():
    (f1, z1, _), (f2, _, _) = modes(PlantModel("nominal"), NOMINAL.vector())
    assert f1 == pytest.approx(1.70, rel=1e-3) and f2 == pytest.approx(1.70, rel=1e-3)
    assert 0.005 < z1 < 0.02


def test_hardware_has_split_low_modes_and_a_parasitic_mode_above_the_bandwidth():
    info = plant_info("hardware")
    freqs = info["natural_frequencies_hz"]
    assert 1.4 < freqs[0] < freqs[1] < 1.9  # mismatch breaks the three-fold symmetry
    assert all(f > 10 * 2.0 for f in freqs[2:])  # far above the 2 Hz crossover
    assert info["workspace_radius_m"] == 0.05


def test_overrides_reach_the_model():
    model = PlantModel("nominal")
    p = model.parameter_values(k_s1=2 * NOMINAL.k_s[0])
    q_stiff = np.array(model.terms([0.02, 0.0], [0, 0], p)[2]).ravel()
    q_base = np.array(model.terms([0.02, 0.0], [0, 0], model.parameter_values())[2]).ravel()
    assert np.linalg.norm(q_stiff) > np.linalg.norm(q_base)
