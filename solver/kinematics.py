"""Vectorised forward kinematics of SMR positions and their analytic identification Jacobian.

The chain tracker -> base -> joints -> flange is written as a list of elementary motions
(rotations and translations about one local axis). Every calibratable quantity is the amount
of one such motion, so every Jacobian column is either `axis x (p - origin)` (rotation) or
`axis` (translation), evaluated for all poses at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from . import chain
from .robot import Robot

AXES = {"x": 0, "y": 1, "z": 2}
BASE_NAMES = ("base_x", "base_y", "base_z", "base_rz", "base_ry", "base_rx")


@dataclass(frozen=True)
class Op:
    """An elementary motion: rotation ('r') or translation ('t') about a local axis."""

    kind: str  # 'r' or 't'
    axis: int  # 0, 1, 2
    param: int  # index in the parameter vector
    joint: int = -1  # joint whose reading is added to the amount (-1: none)


@lru_cache(maxsize=64)
def joint_ops(robot: Robot, first_param: int = 0) -> tuple[Op, ...]:
    """The elementary motions of the arm, from base to flange (cached: layouts are made often)."""
    ops, k = [], first_param
    for i, par in enumerate(robot.parallel):
        theta, d, a, alpha = k, k + 1, k + 2, k + 3
        beta = k + 4 if par else None
        k += 5 if par else 4
        if robot.convention == "dh":
            chain = [Op("r", 2, theta, i), Op("t", 2, d), Op("t", 0, a), Op("r", 0, alpha)]
            if beta is not None:
                chain.append(Op("r", 1, beta))
        else:
            chain = [Op("r", 0, alpha)]
            if beta is not None:
                chain.append(Op("r", 1, beta))
            chain += [Op("t", 0, a), Op("r", 2, theta, i), Op("t", 2, d)]
        ops += chain
    return tuple(ops)


@lru_cache(maxsize=64)
def layout_shape(robot: Robot, target_names: tuple[str, ...]):
    """A layout's geometric parameter count, parameter names and elementary motions (cached:
    layouts are made for every fit and rebasing)."""
    n_geo = len(robot.param_names())
    names = tuple(
        robot.param_names() + list(BASE_NAMES) + [f"{t}_{c}" for t in target_names for c in "xyz"]
    )
    base = (
        Op("t", 0, n_geo),
        Op("t", 1, n_geo + 1),
        Op("t", 2, n_geo + 2),
        Op("r", 2, n_geo + 3),
        Op("r", 1, n_geo + 4),
        Op("r", 0, n_geo + 5),
    )
    return n_geo, names, base + joint_ops(robot)


@dataclass(frozen=True)
class Layout:
    """Index map of the identification vector x = [geometry, base (6), targets (3K)].

    The base is `base_ref @ Trans(x, y, z) @ Rz @ Ry @ Rx` with the six base entries of x;
    base_ref is a fixed reference (from registration), so those entries stay small.
    """

    robot: Robot
    base_ref: np.ndarray
    target_names: tuple[str, ...]

    @cached_property
    def n_geo(self) -> int:
        return self._shape[0]

    @property
    def base_slice(self) -> slice:
        return slice(self.n_geo, self.n_geo + 6)

    @property
    def target_slice(self) -> slice:
        return slice(self.n_geo + 6, self.n_geo + 6 + 3 * len(self.target_names))

    @cached_property
    def n_params(self) -> int:
        return self.n_geo + 6 + 3 * len(self.target_names)

    @cached_property
    def _shape(self):
        return layout_shape(self.robot, self.target_names)

    def names(self) -> tuple[str, ...]:
        return self._shape[1]

    def ops(self) -> tuple[Op, ...]:
        return self._shape[2]

    def pack(self, geometry, base_delta, targets) -> np.ndarray:
        return np.concatenate([geometry, base_delta, np.asarray(targets, float).ravel()])

    def initial(self, targets) -> np.ndarray:
        """x with the robot's own geometry, base equal to base_ref and the given targets."""
        return self.pack(self.robot.param_vector(), np.zeros(6), targets)

    def targets(self, x) -> np.ndarray:
        return np.asarray(x[self.target_slice]).reshape(len(self.target_names), 3)

    def base(self, x) -> np.ndarray:
        """The 4x4 base-in-tracker transform that x describes."""
        tx, ty, tz, rz, ry, rx = x[self.base_slice]
        return self.base_ref @ translation(tx, ty, tz) @ rot(2, rz) @ rot(1, ry) @ rot(0, rx)

    def expressed(self, other: Layout, x) -> np.ndarray:
        """x of `other` (the same robot and SMRs, another base_ref) in this layout: the same
        arm, base and SMRs, its base entries taken against this base_ref."""
        M = np.linalg.solve(self.base_ref, other.base(x))
        R = M[:3, :3]
        y = np.array(x, dtype=float)
        y[self.base_slice] = (
            *M[:3, 3],
            np.arctan2(R[1, 0], R[0, 0]),
            np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)),
            np.arctan2(R[2, 1], R[2, 2]),
        )
        return y

    def rebased(self, x) -> tuple[Layout, np.ndarray]:
        """An equivalent layout whose base_ref absorbs x's base entries (which become zero)."""
        lay = Layout(self.robot, self.base(x), self.target_names)
        y = np.array(x, dtype=float)
        y[self.base_slice] = 0.0
        return lay, y


def rot(axis: int, angle: float) -> np.ndarray:
    """4x4 rotation about x, y or z."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(4)
    m[i, i] = c
    m[j, j] = c
    m[i, j] = -s
    m[j, i] = s
    return m


def translation(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def flange_frames(layout: Layout, x, q, dq=None, record=False, frames=None):
    """Flange frames in the tracker frame for every pose.

    q: (m, n) joint readings in rad; dq: optional (m, n) corrections added to them (model
    extensions). Returns (R (m, 3, 3) with columns as axes, o (m, 3)) and, if record, the
    per-op (op, axis (m, 3), origin (m, 3) or None for translations) the Jacobian needs.
    A `frames` list receives each joint's frame (see joint_frames).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    M = chain.frames(layout.base_ref, q.shape[0])
    rec, cols = [], [M[:, c] for c in range(4)]
    for op in chain.walk(layout.ops(), x, q, M, dq):
        if record:
            # plain copies of M's rows, seen pose-first: a transposing copy costs more
            origin = cols[3].copy().T if op.kind == "r" else None
            rec.append((op, cols[op.axis].copy().T, origin))
        if frames is not None and op.kind == "r" and op.joint >= 0:
            frames.append(chain.split(M))
    R, o = chain.split(M)
    return (R, o, rec) if record else (R, o)


def joint_frames(layout: Layout, x, q, dq=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per joint, the frame (R (m, 3, 3), o (m, 3)) of the body it moves, in the tracker frame.

    Each is taken right after the joint's rotation, so its z axis is the joint axis and it moves
    rigidly with the link that follows the joint.
    """
    frames: list = []
    flange_frames(layout, x, q, dq, frames=frames)
    return frames


def predict(layout: Layout, x, q, dq=None) -> np.ndarray:
    """SMR centres in the tracker frame, shape (m, K, 3)."""
    R, o = flange_frames(layout, x, q, dq)
    t = layout.targets(x)
    return np.einsum("mij,kj->mki", R, t) + o[:, None, :]


def predict_with_jacobian(layout: Layout, x, q, dq=None):
    """SMR centres (m, K, 3), their Jacobian (m, K, 3, P) and d(point)/d(joint angle) (m, K, 3, n).

    The joint-angle derivative lets model extensions that perturb joint angles chain their own
    parameters onto it. The same columns as predict_rows, laid out pose-first.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    m, K, P = q.shape[0], len(layout.target_names), layout.n_params
    mask = np.ones((m, K), dtype=bool)
    p, Jt, Jq = predict_rows(layout, x, q, mask, np.arange(P), dq, joint_cols=True)
    J = np.moveaxis(Jt.reshape(P, m, K, 3), 0, -1)
    Jq = np.moveaxis(Jq.reshape(len(Jq), m, K, 3), 0, -1)
    return p.reshape(m, K, 3), J, Jq


def predict_rows(layout: Layout, x, q, mask, cols, dq=None, joint_cols=False):
    """Predicted SMR centres of the readings in `mask` and the transposed Jacobian of their coordinates.

    Returns p (N, 3) for the N readings where mask (m, K) is true, Jt (len(cols), N, 3) with
    d p / d x[cols[c]] in Jt[c] (parameter-first, so each column is one contiguous block that the
    solvers use as Jt.reshape(len(cols), -1)), and, if joint_cols, Jq (n, N, 3), d p / d q.
    """
    R, o, rec = flange_frames(layout, x, q, dq, record=True)
    t = layout.targets(x)
    full = np.einsum("mij,kj->mki", R, t) + o[:, None, :]  # (m, K, 3)
    m, K = mask.shape
    where = np.full(layout.n_params, -1)
    where[np.asarray(cols, dtype=int)] = np.arange(len(cols))
    n_extra = layout.robot.n_joints if joint_cols else 0
    # Work per pose and target, then keep the measured readings once at the end.
    Jf = np.zeros((len(cols) + n_extra, m, K, 3))
    v = np.empty_like(full)
    for op, axis, origin in rec:
        c = where[op.param]
        jq = len(cols) + op.joint if joint_cols and op.joint >= 0 else -1
        if c < 0 and jq < 0:
            continue
        dst = Jf[c if c >= 0 else jq]
        if op.kind == "t":
            dst[...] = axis[:, None, :]
        else:
            np.subtract(full, origin[:, None, :], out=v)
            w = axis[:, None, :]
            dst[..., 0] = w[..., 1] * v[..., 2] - w[..., 2] * v[..., 1]
            dst[..., 1] = w[..., 2] * v[..., 0] - w[..., 0] * v[..., 2]
            dst[..., 2] = w[..., 0] * v[..., 1] - w[..., 1] * v[..., 0]
        if c >= 0 and jq >= 0:
            Jf[jq] = dst
    ts = layout.target_slice.start
    for k in range(K):
        for ax in range(3):
            c = where[ts + 3 * k + ax]
            if c >= 0:
                Jf[c, :, k] = R[:, :, ax]
    if mask.all():
        p, Jf = full.reshape(-1, 3), Jf.reshape(Jf.shape[0], -1, 3)
    else:
        p, Jf = full[mask], Jf[:, mask]
    Jt = Jf[: len(cols)]
    return (p, Jt, Jf[len(cols) :]) if joint_cols else (p, Jt)
