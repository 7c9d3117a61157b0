"""Gravity on the arm: the torque each joint carries per unit of the links' masses, a nominal mass
model's weights of it, and gravity's direction in the base frame (the compliance effect's physics)."""

from __future__ import annotations

import numpy as np

from .finite import finite
from .kinematics import Layout, joint_frames

DOWN = np.array([0.0, 0.0, -1.0])  # gravity in a levelled tracker's frame


LINK_TERMS = 4  # gravity_basis's columns per link: its mass and three first mass moments


def gravity_basis(layout: Layout, x, q, joint: int, gravity: np.ndarray) -> np.ndarray:
    """Gravity torque on a joint per unit of each link's mass and first mass moments, (m, 4 (n - j)).

    The torque about joint j of a link i >= j with mass m_i and centre of gravity r_i (in the link's
    frame R_i, o_i) is z_j . ((o_i - o_j + R_i r_i) x m_i g): linear in m_i and m_i r_i, whose values
    (unknown on a real arm) become the fitted coefficients.
    """
    lay = Layout(layout.robot, np.eye(4), layout.target_names)  # base frame
    frames = joint_frames(lay, x, q)
    Rj, oj = frames[joint]
    zj = Rj[:, :, 2]
    cols = []
    for Ri, oi in frames[joint:]:
        cols.append(np.einsum("mi,mi->m", zj, np.cross(oi - oj, gravity)))
        for a in range(3):
            cols.append(np.einsum("mi,mi->m", zj, np.cross(Ri[:, :, a], gravity)))
    return np.stack(cols, axis=1) / 1000.0  # per metre of lever: coefficients in N m-ish units


# The wrist, its motors and the tool, lumped at the last joint: this share of the links' mass.
WRIST_SHARE = 0.25


def nominal_masses(layout: Layout, x, joint: int) -> np.ndarray:
    """Weights of gravity_basis(joint)'s columns for a nominal mass model: each link a uniform
    rod from its joint to the next (mass per metre of length), the wrist lumped at the last
    joint. The arm's real masses are unknown; their shape, not their scale, sets the torque a
    single stiffness multiplies (its scale is the fitted coefficient)."""
    lay = Layout(layout.robot, np.eye(4), layout.target_names)
    frames = joint_frames(lay, x, np.zeros((1, layout.robot.n_joints)))
    rods: list[tuple[float, np.ndarray]] = []
    for (R, o), (_, o_next) in zip(frames[:-1], frames[1:]):
        half = (o_next[0] - o[0]) / 2.0
        rods.append((float(np.linalg.norm(2.0 * half)) / 1000.0, R[0].T @ half))  # kg per m, mm
    # the wrist, a share of the arm's mass, lumped at the last joint's origin
    rods.append((WRIST_SHARE * sum(m for m, _ in rods), np.zeros(3)))
    return np.concatenate([[m, *(m * r)] for m, r in rods[joint:]])


def gravity_in_base(layout: Layout, x) -> np.ndarray:
    """Gravity direction in the robot base frame, assuming the tracker is levelled (z up)."""
    return layout.base(x)[:3, :3].T @ DOWN


def select_independent(B: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Columns of B independent of each other and of a constant (which a joint offset absorbs)."""
    from scipy.linalg import qr

    A = B - B.mean(axis=0)
    norms = np.linalg.norm(A, axis=0)
    keep = np.zeros(B.shape[1], dtype=bool)
    live = np.flatnonzero(norms > tol * max(norms.max(), 1e-300))
    if len(live) == 0:
        return keep
    _, R, piv = qr(
        finite(A[:, live] / norms[live], "an effect's basis"), mode="economic", pivoting=True
    )
    rank = int(np.sum(np.abs(np.diag(R)) > tol * abs(R[0, 0])))
    keep[live[piv[:rank]]] = True
    return keep


# A joint is a usual suspect of compliance when the nominal gravity torque it carries varies over
# the campaign at least this share of the most loaded joint's: the shoulder and elbow of a serial
# arm, far from the wrist's few percent (the nominal model lumps the wrist at the last joint).
SUSPECT_SHARE = 0.25


def gravity_spread(layout: Layout, x, q: np.ndarray) -> np.ndarray:
    """Each joint's spread (standard deviation) of nominal gravity torque over the poses q."""
    g = gravity_in_base(layout, x)
    return np.array(
        [
            np.std(gravity_basis(layout, x, q, j, g) @ nominal_masses(layout, x, j))
            for j in range(layout.robot.n_joints)
        ]
    )


def gravity_suspects(layout: Layout, x, q: np.ndarray) -> list[int]:
    """The joints (0-based) whose nominal gravity torque varies most over the poses q: those that
    carry the arm's weight, where a compliance is the physics' first guess."""
    spread = gravity_spread(layout, x, q)
    if not spread.max() > 0:
        return []
    return [int(j) for j in np.flatnonzero(spread >= SUSPECT_SHARE * spread.max())]


def most_loaded(layout: Layout, x, q: np.ndarray) -> int | None:
    """The joint (0-based) whose nominal gravity torque varies most over the poses q, if any."""
    spread = gravity_spread(layout, x, q)
    return int(np.argmax(spread)) if spread.max() > 0 else None
