"""Preprocessing against independent references: finite differences, a pure sine, geometry."""

import numpy as np
import pytest

from flexff.controllers.features import (
    DIRECTION_WIDTHS,
    FEATURE_SETS,
    feature_names,
    feature_units,
    motion_columns,
    motion_features,
    motion_function,
    reference_features,
)
from flexff.learning.dataset import REFERENCE_SIGNALS
from flexff.learning.features import (
    FeatureConfig,
    encoder_positions,
    prepare_trajectory,
    quantize_encoders,
)
from flexff.learning.samples import MAP_CHUNK, evaluate_samples
from flexff.learning.scaling import MinMaxScaler
from flexff.learning.signal_processing import decimation, differentiate, lowpass
from flexff.learning.synthetic import skew_sine_circle, synthetic_trajectory
from flexff.plant.kinematics import COORDINATE_NAMES, SHOULDER_INDEX


def test_chain_rule_velocities_match_finite_differences_of_the_coordinates(nominal):
    t = np.linspace(0.0, 3.0, 3001)
    motion = skew_sine_circle(t, 3.0, radius=0.03, turns=2, start_angle=0.4).T
    feats = motion_features(motion[:, 0:2], motion[:, 2:4], motion[:, 4:6], "full")
    p = nominal.parameter_values()
    q = np.asarray(nominal.coordinates.map(len(t))(motion[:, 0:2].T, p)).T
    h = t[1] - t[0]
    # fourth-order central differences of the 21 coordinates themselves
    qd = (-q[4:] + 8 * q[3:-1] - 8 * q[1:-3] + q[:-4]) / (12 * h)
    qdd = (-q[4:] + 16 * q[3:-1] - 30 * q[2:-2] + 16 * q[1:-3] - q[:-4]) / (12 * h**2)
    np.testing.assert_allclose(feats[:, :21], q, atol=1e-12)
    velocity, acceleration = feats[2:-2, 21:42], feats[2:-2, 42:]
    assert np.abs(velocity - qd).max() < 1e-8 * np.abs(velocity).max()
    assert np.abs(acceleration - qdd).max() < 1e-6 * np.abs(acceleration).max()


@pytest.mark.parametrize("n", [1, MAP_CHUNK, 2 * MAP_CHUNK + 5])
def test_samples_evaluated_in_chunks_equal_one_call_each(n):
    rng = np.random.default_rng(n)
    pos, vel, acc = (rng.normal(0, s, (n, 2)) for s in (0.01, 0.05, 0.5))
    got = evaluate_samples(motion_function("full"), pos, vel, acc)
    some = sorted({0, n // 2, n - 1})
    expected = [np.asarray(motion_function("full")(pos[k], vel[k], acc[k])).ravel()
                for k in some]
    assert got.shape == (n, 63)
    np.testing.assert_array_equal(got[some], expected)


def test_direction_features_are_the_full_set_and_each_motors_smoothed_direction():
    t = np.linspace(0.0, 3.0, 301)
    motion = skew_sine_circle(t, 3.0, radius=0.03, turns=2, start_angle=0.4).T
    columns = motion[:, 0:2], motion[:, 2:4], motion[:, 4:6]
    full, directions = (motion_features(*columns, s) for s in ("full", "directions"))
    np.testing.assert_array_equal(directions[:, :63], full)
    motors = full[:, [21 + k for k in SHOULDER_INDEX]]  # theta_s1..3_dot (chain rule, above)
    expected = np.hstack([np.tanh(motors / w) for w in DIRECTION_WIDTHS])
    np.testing.assert_allclose(directions[:, 63:], expected, atol=1e-15)
    assert feature_names("directions")[63:66] == [f"tanh(theta_s{k}_dot/0.003)" for k in (1, 2, 3)]
    # every motor turns both ways on two turns of a circle: each feature spans its range
    assert np.all(directions[:, 63:66].max(axis=0) > 0.99)
    assert np.all(directions[:, 63:66].min(axis=0) < -0.99)


def test_compact_features_are_the_motion_itself():
    rng = np.random.default_rng(1)
    pos, vel, acc = (rng.normal(0, s, (10, 2)) for s in (0.02, 0.1, 1.0))
    np.testing.assert_array_equal(motion_features(pos, vel, acc, "compact"),
                                  np.hstack([pos, vel, acc]))


@pytest.mark.parametrize("feature_set", FEATURE_SETS)
def test_motion_columns_point_at_the_wrist_signals(feature_set):
    rng = np.random.default_rng(2)
    pos, vel, acc = (rng.normal(0, s, (5, 2)) for s in (0.02, 0.1, 1.0))
    feats = motion_features(pos, vel, acc, feature_set)
    cols = motion_columns(feature_set)
    for c, expected in zip(cols, (pos, vel, acc)):
        np.testing.assert_allclose(feats[:, c], expected, atol=1e-15)
    assert len(feature_names(feature_set)) == feats.shape[1] == len(feature_units(feature_set))


def test_feature_names_follow_eq_2_1():
    names = feature_names("full")
    assert len(names) == 63 and names[:21] == list(COORDINATE_NAMES)
    assert names[21] == "x_up1_dot" and names[62] == "theta_ee_ddot"


def test_zero_phase_filter_passes_a_slow_sine_without_delay():
    rate = 1000.0
    t = np.arange(20000) / rate
    slow = np.sin(2 * np.pi * 0.3 * t)
    out = lowpass(slow, rate, 1.8, 4)
    middle = slice(5000, 15000)
    assert np.abs(out[middle] - slow[middle]).max() < 1e-3  # no lag, no loss at 0.3 Hz
    lag = np.argmax(np.correlate(out[middle], slow[middle], "full")) - (10000 - 1)
    assert lag == 0


def test_filter_removes_fast_noise():
    rate = 1000.0
    t = np.arange(10000) / rate
    fast = np.sin(2 * np.pi * 40 * t)
    assert np.abs(lowpass(fast, rate)[3000:7000]).max() < 1e-6  # away from the end transients


def test_differentiate_a_polynomial_exactly_inside():
    rate = 100.0
    t = np.arange(200) / rate
    pos = np.column_stack([t**2, 3 * t])
    vel, acc = differentiate(pos, rate)
    np.testing.assert_allclose(vel[2:-2], np.column_stack([2 * t, 3 + 0 * t])[2:-2], atol=1e-12)
    np.testing.assert_allclose(acc[2:-2, 0], 2.0, atol=1e-9)


@pytest.mark.parametrize("encoders", [2, 3])
def test_encoder_positions_invert_the_shoulder_angles(nominal, encoders):
    p = nominal.parameter_values()
    points = np.array([[0.0, 0.0], [0.03, -0.02], [-0.04, 0.01]])
    theta = np.array([[float(np.asarray(nominal.coordinates(pt, p))[k, 0]) for k in SHOULDER_INDEX]
                      for pt in points])
    np.testing.assert_allclose(encoder_positions(theta, encoders), points, atol=1e-10)


def test_quantization_counts_from_home_like_the_plant_encoders(nominal):
    p = nominal.parameter_values()
    home = np.array([float(np.asarray(nominal.coordinates([0.0, 0.0], p))[k, 0])
                     for k in SHOULDER_INDEX])
    count = 2 * np.pi / 2048
    rng = np.random.default_rng(4)
    theta = home + rng.uniform(-0.2, 0.2, (500, 3))
    counted = quantize_encoders(theta)
    steps = (counted - home) / count
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    assert np.abs(counted - theta).max() <= count / 2 + 1e-12
    np.testing.assert_array_equal(quantize_encoders(counted), counted)  # already counted: kept
    np.testing.assert_array_equal(quantize_encoders(home[None, :]), home[None, :])


def test_scaler_maps_training_data_to_unit_interval_and_back():
    rng = np.random.default_rng(3)
    train = [rng.normal(5, 2, (50, 3)), rng.normal(-1, 1, (30, 3))]
    train[0][:, 2] = 7.0  # a constant column keeps a unit span
    scaler = MinMaxScaler.fit(train)
    z = scaler.transform(np.vstack(train))
    assert z.min(axis=0)[:2] == pytest.approx([0, 0]) and z.max(axis=0)[:2] == pytest.approx([1, 1])
    assert np.all(np.isfinite(z))
    np.testing.assert_allclose(scaler.inverse(z), np.vstack(train))
    assert MinMaxScaler.from_dict(scaler.to_dict()).transform(train[1]) == pytest.approx(
        scaler.transform(train[1]))


def test_prepare_trajectory_down_samples_and_adds_noise_only_with_a_generator():
    traj = synthetic_trajectory("a", "train", seed=5, duration=4.0, rate_hz=1000.0)
    config = FeatureConfig(model_rate_hz=100.0)
    x1, f1 = prepare_trajectory(traj, 1000.0, config)
    x2, f2 = prepare_trajectory(traj, 1000.0, config)
    assert x1.shape == (400, 63) and f1.shape == (400, 2)
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(f1, f2)
    x3, _ = prepare_trajectory(traj, 1000.0, config, np.random.default_rng(0))
    assert not np.array_equal(x1, x3)
    # filtered encoder positions follow the true motion to within the quantization (about 1 mm)
    true = np.column_stack([traj.signals["x"], traj.signals["y"]])[::10]
    assert np.abs(x1[:, 18:20] - true)[50:-50].max() < 1.5e-3


def test_reference_features_use_the_same_function():
    traj = synthetic_trajectory("b", "test", seed=6, duration=2.0, rate_hz=100.0)
    ref = np.column_stack([traj.signals[s] for s in REFERENCE_SIGNALS])
    np.testing.assert_array_equal(reference_features(traj.signals, "full"),
                                  motion_features(ref[:, 0:2], ref[:, 2:4], ref[:, 4:6], "full"))


def test_bad_feature_settings_are_refused():
    with pytest.raises(ValueError, match="feature set"):
        FeatureConfig(feature_set="all")
    with pytest.raises(ValueError, match="encoders"):
        FeatureConfig(encoders=1)
    with pytest.raises(ValueError, match="whole number"):
        decimation(1000.0, 300.0)
    with pytest.raises(ValueError, match="Nyquist"):
        lowpass(np.zeros(100), 3.0, 1.8)
