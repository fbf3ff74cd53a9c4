"""Kinematics against independent references: geometry, the thesis's appendix C, least squares."""

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import least_squares

from flexff.plant.kinematics import check_workspace
from flexff.plant.parameters import NOMINAL
from tests.helpers import workspace_points

L, R = NOMINAL.l_up, NOMINAL.r_mount
MOUNTS = [R * np.array([np.cos(np.radians(a)), np.sin(np.radians(a))]) for a in (90, -30, 210)]


def unit(angle):
    return np.array([np.cos(angle), np.sin(angle)])


def test_inverse_kinematics_satisfies_the_geometry(nominal, rng):
    p = nominal.parameter_values()
    for pos in workspace_points(rng, 40).T:
        q = np.array(nominal.coordinates(pos, p)).ravel()
        lower_angles = []
        for i, m in enumerate(MOUNTS):
            up, th_s = q[6 * i:6 * i + 2], q[6 * i + 2]
            low, th_e = q[6 * i + 3:6 * i + 5], q[6 * i + 5]
            elbow = m + L * unit(th_s)
            assert np.allclose(up, m + L / 2 * unit(th_s), atol=1e-13)
            assert np.allclose(low, elbow + L / 2 * unit(th_s + th_e), atol=1e-13)
            assert np.allclose(elbow + L * unit(th_s + th_e), pos, atol=1e-13)
            # the thesis's eq. (C.3): elbow angle from the motor-to-wrist distance
            reach = np.linalg.norm(pos - m)
            assert th_e == pytest.approx(np.arccos((reach**2 - 2 * L**2) / (2 * L**2)), abs=1e-12)
            lower_angles.append(th_s + th_e)
        assert np.allclose(q[18:20], pos)
        assert q[20] == pytest.approx(np.mean(lower_angles), abs=1e-13)


def test_elbow_branch_at_the_centre_is_the_symmetric_one(nominal):
    q = np.array(nominal.coordinates([0, 0], nominal.parameter_values())).ravel()
    # r_mount = sqrt(2) l puts every elbow at 90 degrees, bent the same way
    assert np.allclose(q[[5, 11, 17]], np.pi / 2, atol=1e-12)
    assert np.allclose(np.diff(q[[2, 8, 14]] % (2 * np.pi)) % (2 * np.pi), 4 * np.pi / 3,
                       atol=1e-12)


@pytest.mark.parametrize("encoders", [2, 3])
def test_forward_kinematics_round_trip_of_all_21_coordinates(nominal, rng, encoders):
    p = nominal.parameter_values()
    fk = nominal.fk2 if encoders == 2 else nominal.fk3
    for pos in workspace_points(rng, 60).T:
        q = np.array(nominal.coordinates(pos, p)).ravel()
        back = np.array(fk(q[[2, 8, 14][:encoders]], p)).ravel()
        assert np.allclose(back, pos, atol=1e-10, rtol=0)
        q_back = np.array(nominal.coordinates(back, p)).ravel()
        assert np.allclose(q_back, q, atol=1e-10, rtol=0)


def test_three_encoder_forward_kinematics_is_the_least_squares_solution(nominal, rng):
    p = nominal.parameter_values()
    resolution = 2 * np.pi / 2048
    errors = {2: [], 3: []}  # distance of each estimate from the true position
    for pos in workspace_points(rng, 10, radius=0.045).T:
        q = np.array(nominal.coordinates(pos, p)).ravel()
        measured = q[[2, 8, 14]] + rng.uniform(-resolution / 2, resolution / 2, 3)
        ours = np.array(nominal.fk3(measured, p)).ravel()

        def residual(z, measured=measured):
            return np.array(nominal.coordinates(z, p)).ravel()[[2, 8, 14]] - measured

        reference = least_squares(residual, pos, xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        assert np.allclose(ours, reference, atol=1e-10)
        assert np.linalg.norm(ours - pos) < 3 * resolution * L
        for _ in range(40):  # quantization-like noise on every encoder, the same for both
            noisy = q[[2, 8, 14]] + rng.uniform(-resolution / 2, resolution / 2, 3)
            for encoders, fk in ((2, nominal.fk2), (3, nominal.fk3)):
                estimate = np.array(fk(noisy[:encoders], p)).ravel()
                errors[encoders].append(np.linalg.norm(estimate - pos))
    # and averaging three encoders beats the two-encoder solution on average: over 400 noisy
    # readings the mean error is 0.64x to 0.75x the two-encoder one's (measured on 30 seeds)
    assert np.mean(errors[3]) < 0.85 * np.mean(errors[2])


def test_jacobians_match_finite_differences(nominal, rng):
    p = nominal.parameter_values()
    pos_sym = ca.SX.sym("pos", 2)
    q_jac = ca.Function("qj", [pos_sym], [ca.jacobian(nominal.coordinates(pos_sym, p), pos_sym)])
    h = 1e-6
    for pos in workspace_points(rng, 10).T:
        analytic_q = np.array(q_jac(pos))
        analytic_a = np.array(nominal.terms(pos, [0, 0], p)[4])
        numeric = np.column_stack([
            (np.array(nominal.coordinates(pos + h * e, p))
             - np.array(nominal.coordinates(pos - h * e, p))).ravel() / (2 * h)
            for e in np.eye(2)])
        assert np.allclose(analytic_q, numeric, atol=1e-7)
        assert np.allclose(analytic_a, numeric[[2, 8, 14]], atol=1e-7)


def test_workspace_check_names_the_point():
    check_workspace(NOMINAL, [0.0, 0.03], [0.05, 0.0])
    with pytest.raises(ValueError, match=r"\(0.06, 0\) m lies outside the workspace.*0.05 m"):
        check_workspace(NOMINAL, [0.0, 0.06], [0.0, 0.0])
    with pytest.raises(ValueError, match="non-finite"):
        check_workspace(NOMINAL, [np.nan], [0.0])
