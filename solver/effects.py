"""Non-geometric model extensions, each linear in its own parameters.

A joint extension adds a correction dq_j = basis(q) @ c to one joint's reading (cyclic gear
error, scale error, compliance under gravity). A point extension moves the predicted SMR centres
after the kinematics (links growing with temperature, the base moving during the campaign).
Bases are computed once per data set from the registered nominal model, so the extended model
stays linear in the new parameters and their Jacobian is the joint's column times the basis.
What each effect is (basis, parameters, report, file form) lives in its class in vocabulary.py;
the functions here only dispatch to it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .finite import finite
from .kinematics import Layout, joint_frames
from .motion import last_motion

DOWN = np.array([0.0, 0.0, -1.0])  # gravity in a levelled tracker's frame


@dataclass
class Inputs:
    """What extensions depend on, per pose and reading: joints, time, temperature, last motion."""

    q: np.ndarray  # (m, n) rad
    time_s: np.ndarray | None = None  # (m, K)
    temp_c: np.ndarray | None = None  # (m, K)
    # (m, n) sign of each joint's last move before the pose, from the whole campaign's order
    motion: np.ndarray | None = None
    # (m, n) rad the joints the arm came from (NaN rows: not given); they decide the motion
    prev_q: np.ndarray | None = None

    def __post_init__(self):
        if self.motion is None:
            self.motion = last_motion(self.q, self.time_s, self.prev_q)

    def subset(self, idx) -> Inputs:
        pick = lambda a: None if a is None else a[idx]  # noqa: E731
        return Inputs(
            self.q[idx], pick(self.time_s), pick(self.temp_c), pick(self.motion), pick(self.prev_q)
        )


@dataclass
class Extension:
    """One extension: its kind, where it acts, and its fitted coefficients."""

    name: str
    joint: int | None = None  # 0-based
    harmonic: int | None = None
    at_s: float | None = None
    t_ref: float | None = None  # thermal: temperature (or time) of zero growth
    variable: str | None = None  # thermal: "temp_c" or "time_s"
    origin: np.ndarray | None = None  # base shift: centre of the rotation (the data's centroid)
    coef: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # compliance: raw gravity-basis columns kept and the gravity direction in the base frame
    keep: np.ndarray | None = None
    gravity: np.ndarray | None = None
    # compliance under the nominal mass model: fixed weights of the raw gravity basis (one
    # stiffness fitted), instead of the kept columns' masses fitted one by one
    masses: np.ndarray | None = None

    @property
    def kind(self):
        """Its class in the vocabulary (solver.vocabulary), which knows everything else about it."""
        from .vocabulary import KINDS  # the vocabulary builds on this module

        return KINDS[self.name]

    @property
    def is_joint(self) -> bool:
        return self.kind.is_joint

    @property
    def n_params(self) -> int:
        return self.kind.n_params(self)

    def label(self) -> str:
        return self.kind.label(self)


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


def joint_basis(ext: Extension, layout: Layout, x, inputs: Inputs) -> np.ndarray:
    """(m, P) basis of a joint extension: dq_joint = basis @ coef."""
    if not ext.is_joint:
        raise ValueError(f"{ext.name} is not a joint extension")
    return ext.kind.basis(ext, layout, x, inputs)


def point_basis(ext: Extension, layout: Layout, x, inputs: Inputs):
    """Per reading (m, K): the scalar that switches or scales a point extension."""
    if ext.is_joint:
        raise ValueError(f"{ext.name} is not a point extension")
    return ext.kind.basis(ext, layout, x, inputs)


def prepare(ext: Extension, layout: Layout, x, inputs: Inputs) -> np.ndarray:
    """The extension's basis on this data: (m, P) for joint extensions, (m, K) for point ones."""
    return (
        joint_basis(ext, layout, x, inputs) if ext.is_joint else point_basis(ext, layout, x, inputs)
    )


def joint_offsets(exts, bases, n_joints: int) -> np.ndarray | None:
    """Sum of the joint corrections (m, n) of the joint extensions."""
    dq = None
    for ext, B in zip(exts, bases):
        if ext.is_joint:
            if dq is None:
                dq = np.zeros((B.shape[0], n_joints))
            dq[:, ext.joint] += B @ ext.coef
    return dq


def point_shift(ext: Extension, s: np.ndarray, p: np.ndarray, origin: np.ndarray, coef=None):
    """Displacement (N, 3) of points p by a point extension and its Jacobian (P, N, 3).

    s is the extension's per-reading scalar; origin the point it acts about (`kind.origin`).
    """
    return ext.kind.shift(ext, s, p - origin, ext.coef if coef is None else coef)
