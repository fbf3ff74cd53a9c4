"""Kinematics of the three-chain manipulator, written once for numbers and CasADi symbols.

Chain i: a motor at M_i on a circle of radius r_mount (90, -30 and 210 degrees) turns the
upper arm to absolute angle theta_si; the elbow hinge E_i = M_i + l_up u(theta_si) carries the
lower arm at absolute angle theta_si + theta_ei (theta_ei is the elbow's relative angle, as in
the thesis's appendix C); the three lower arms meet at the wrist hinge (x_ee, y_ee), whose
rotation theta_ee is the mean of the three lower-arm angles. The elbows bend the same way in
every chain (the branch that holds at the centre: each upper arm turned clockwise from the
line motor -> end effector).

The 21 generalized coordinates follow eq. (2.1): per chain (x_up, y_up, theta_s, x_low, y_low,
theta_e), then (x_ee, y_ee, theta_ee); arm positions are centres of mass.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from flexff.fmu.errors import InputError
from flexff.plant.parameters import PlantParameters

MOUNT_ANGLES_DEG = (90.0, -30.0, 210.0)
COORDINATE_NAMES = (*(f"{name}{i}" for i in (1, 2, 3)
                      for name in ("x_up", "y_up", "theta_s", "x_low", "y_low", "theta_e")),
                    "x_ee", "y_ee", "theta_ee")
N_COORDINATES = len(COORDINATE_NAMES)  # 21
SHOULDER_INDEX = (2, 8, 14)
ELBOW_INDEX = (5, 11, 17)
EE_INDEX = (18, 19, 20)


def mount(p: PlantParameters, chain: int) -> tuple[Any, Any]:
    """Position of motor (shoulder hinge) `chain` (0-based) in m."""
    a = math.radians(MOUNT_ANGLES_DEG[chain])
    return p.r_mount * math.cos(a), p.r_mount * math.sin(a)


@dataclass(frozen=True)
class ChainPose:
    """One chain for the wrist at a given point: elbow position and arm directions (unit)."""

    mount: tuple[Any, Any]
    elbow: tuple[Any, Any]
    upper: tuple[Any, Any]  # unit vector shoulder -> elbow
    lower: tuple[Any, Any]  # unit vector elbow -> wrist


def chain_poses(p: PlantParameters, x: Any, y: Any) -> list[ChainPose]:
    """Inverse kinematics of the three chains, algebraically (law of cosines, no trigonometry).

    The upper arm is the motor -> wrist direction turned clockwise by the angle alpha between
    upper arm and that line; this is the elbow branch that holds at the centre.
    """
    poses = []
    for i in range(3):
        mx, my = mount(p, i)
        dx, dy = x - mx, y - my
        reach = ca.sqrt(dx**2 + dy**2)
        cos_a = (p.l_up**2 + reach**2 - p.l_low**2) / (2 * p.l_up * reach)
        sin_a = ca.sqrt(1 - cos_a**2)
        ux, uy = (cos_a * dx + sin_a * dy) / reach, (cos_a * dy - sin_a * dx) / reach
        ex, ey = mx + p.l_up * ux, my + p.l_up * uy
        poses.append(ChainPose((mx, my), (ex, ey), (ux, uy),
                               ((x - ex) / p.l_low, (y - ey) / p.l_low)))
    return poses


def _angle(u: tuple[Any, Any]) -> Any:
    return ca.atan2(u[1], u[0])


def _angle_between(a: tuple[Any, Any], b: tuple[Any, Any]) -> Any:
    """Signed rotation [rad] that turns unit vector a into unit vector b."""
    return ca.atan2(a[0] * b[1] - a[1] * b[0], a[0] * b[0] + a[1] * b[1])


def shoulder_angles(p: PlantParameters, x: Any, y: Any) -> list[Any]:
    """Absolute upper-arm angles theta_s1..3 [rad] that put the wrist at (x, y)."""
    return [_angle(pose.upper) for pose in chain_poses(p, x, y)]


def generalized_coordinates(p: PlantParameters, x: Any, y: Any) -> Any:
    """Inverse kinematics: the 21 coordinates of eq. (2.1) for the wrist at (x, y)."""
    q, lower_angles = [], []
    for i, pose in enumerate(chain_poses(p, x, y)):
        (mx, my), (ex, ey), up, low = pose.mount, pose.elbow, pose.upper, pose.lower
        theta_s, theta_e = _angle(up), _angle_between(up, low)
        lower_angles.append(theta_s + theta_e)
        q += [mx + p.c_up[i] * up[0], my + p.c_up[i] * up[1], theta_s,
              ex + p.c_low[i] * low[0], ey + p.c_low[i] * low[1], theta_e]
    q += [x, y, (lower_angles[0] + lower_angles[1] + lower_angles[2]) / 3]
    return ca.vertcat(*q)


def flexure_deflections(p: PlantParameters, x: Any, y: Any) -> ca.SX:
    """The nine flexure rotations [rad] from the rest pose (wrist at the centre).

    Shoulders 1-3, elbows 1-3 (lower arm relative to upper arm), wrists 1-3 (lower arm
    relative to the wrist body, which turns by the mean lower-arm rotation, eq. C.3).
    """
    shoulders, lowers = [], []
    for pose, rest in zip(chain_poses(p, x, y), chain_poses(p, 0.0, 0.0)):
        shoulders.append(_angle_between(rest.upper, pose.upper))
        lowers.append(_angle_between(rest.lower, pose.lower))
    wrist = (lowers[0] + lowers[1] + lowers[2]) / 3
    deflections: ca.SX = ca.vertcat(*shoulders, *[lw - sh for lw, sh in zip(lowers, shoulders)],
                                    *[lw - wrist for lw in lowers])
    return deflections


def _elbow(p: PlantParameters, chain: int, theta_s: Any) -> tuple[Any, Any]:
    mx, my = mount(p, chain)
    return mx + p.l_up * ca.cos(theta_s), my + p.l_up * ca.sin(theta_s)


@functools.cache
def _branch_sign() -> float:
    """Which of the two circle intersections is the wrist: fixed by the assembly branch.

    Evaluated once on the design geometry: the two intersections only swap where the two
    elbows coincide, far outside any reachable configuration.
    """
    from flexff.plant.parameters import NOMINAL

    t1, t2, _ = (float(a) for a in shoulder_angles(NOMINAL, 0.0, 0.0))
    guess = _intersection(NOMINAL, t1, t2, 1.0)
    return 1.0 if float(ca.norm_2(ca.vertcat(*guess))) < 1e-9 else -1.0


def _intersection(p: PlantParameters, theta_s1: Any, theta_s2: Any, sign: float) -> tuple[Any, Any]:
    (ax, ay), (bx, by) = _elbow(p, 0, theta_s1), _elbow(p, 1, theta_s2)
    dx, dy = bx - ax, by - ay
    dist = ca.sqrt(dx**2 + dy**2)
    height = ca.sqrt(p.l_low**2 - (dist / 2) ** 2)
    return ((ax + bx) / 2 - sign * height * dy / dist, (ay + by) / 2 + sign * height * dx / dist)


def forward_kinematics_2(p: PlantParameters, theta_s1: Any, theta_s2: Any) -> tuple[Any, Any]:
    """Wrist position from the encoders of chains 1 and 2 (the thesis's choice)."""
    return _intersection(p, theta_s1, theta_s2, _branch_sign())


def forward_kinematics_2_text(p: PlantParameters, theta_s1: str, theta_s2: str) -> tuple[str, str]:
    """forward_kinematics_2 as the text of two expressions (fmu.expressions) of the signals
    named `theta_s1`, `theta_s2`: a machine description's kinematic map."""
    def elbow(chain: int, theta: str) -> tuple[str, str]:  # _elbow's
        mx, my = mount(p, chain)
        return f"({mx!r} + {p.l_up!r} * cos({theta}))", f"({my!r} + {p.l_up!r} * sin({theta}))"

    (ax, ay), (bx, by) = elbow(0, theta_s1), elbow(1, theta_s2)
    dx, dy = f"({bx} - {ax})", f"({by} - {ay})"
    dist = f"sqrt({dx} ** 2 + {dy} ** 2)"
    height = f"sqrt({p.l_low!r} ** 2 - ({dist} / 2) ** 2)"
    minus, plus = ("-", "+") if _branch_sign() > 0 else ("+", "-")
    return (f"({ax} + {bx}) / 2 {minus} {height} * {dy} / {dist}",
            f"({ay} + {by}) / 2 {plus} {height} * {dx} / {dist}")


def forward_kinematics_3(p: PlantParameters, thetas: Any, iterations: int = 4) -> tuple[Any, Any]:
    """Least-squares wrist position from all three encoders (CasADi SX in and out).

    Minimizes sum_i (theta_si(x, y) - measured_i)^2 by Gauss-Newton, started from the
    2-encoder solution; a fixed iteration count keeps it a plain expression for code generation.
    With consistent angles it returns the exact position; with quantized ones it averages.
    """
    z = ca.SX.sym("z", 2)
    residual = (ca.vertcat(*shoulder_angles(p, z[0], z[1]))
                - ca.vertcat(*[thetas[k] for k in range(3)]))
    jac = ca.jacobian(residual, z)
    update = z - ca.solve(jac.T @ jac, jac.T @ residual)
    pos = ca.vertcat(*forward_kinematics_2(p, thetas[0], thetas[1]))
    for _ in range(iterations):
        pos = ca.substitute(update, z, pos)
    return pos[0], pos[1]


def check_workspace(p: PlantParameters, x: Any, y: Any, what: str = "point") -> None:
    """Raise InputError if any (x, y) [m] lies outside the workspace disc or is not finite."""
    xs, ys = np.atleast_1d(np.asarray(x, dtype=float)), np.atleast_1d(np.asarray(y, dtype=float))
    if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ys))):
        raise InputError(f"{what} has non-finite coordinates")
    radius = np.hypot(xs, ys)
    k = int(np.argmax(radius))
    if radius[k] > float(p.workspace_radius):
        raise InputError(
            f"{what} ({xs[k]:.6g}, {ys[k]:.6g}) m lies outside the workspace: its distance "
            f"{radius[k]:.6g} m from the centre exceeds the workspace radius "
            f"{float(p.workspace_radius):.6g} m")
