"""The one walk along the kinematic chain, one elementary motion at a time, for all poses."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

PAIRS = ((1, 2), (2, 0), (0, 1))  # (i, j) with e_a = e_i x e_j


def walk(ops, x, q, M: np.ndarray, dq=None, reverse=False) -> Iterator:
    """Apply the elementary motions ops (kinematics.Op, base to flange) to the frames M in place.

    M (3, 4, m): [R | o] per pose, pose-last so every step is a long vector operation. Forward,
    M becomes M @ op1 @ op2 ...; each op is yielded after it is applied, so M[:, op.axis] is its
    axis and, for a rotation, M[:, 3] a point on it. Reverse (walked from the flange), M becomes
    op1 @ op2 ... @ M; each op is yielded before it is applied, so M holds the rest of the chain
    in the op's own frame (whence its twist). q: (m, n) joint readings in rad; dq: optional
    corrections added to them. At a hundred poses every numpy call costs more than its
    arithmetic, so the joints' sines and cosines are taken in one call each and constant
    amounts stay Python floats.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    t1, t2 = np.empty((4, M.shape[2])), np.empty((4, M.shape[2]))
    xs = np.asarray(x, dtype=float).tolist()
    moving = [op for op in ops if op.joint >= 0]
    if moving:
        amount = (
            q.T[[op.joint for op in moving]] + np.array([xs[op.param] for op in moving])[:, None]
        )
        if dq is not None:
            amount += np.asarray(dq, dtype=float).T[[op.joint for op in moving]]
        cos, sin = np.cos(amount), np.sin(amount)
        row = {id(op): i for i, op in enumerate(moving)}
    # views made once: at a hundred poses slicing per motion costs as much as the arithmetic
    shift = M[:, 3]  # the translation column, moved by M @ Trans
    if reverse:  # rows: Rot @ M
        lines, ti, tj = [M[i] for i in range(3)], t1, t2
    else:  # columns: M @ Rot
        lines, ti, tj = [M[:, i] for i in range(3)], t1[:3], t2[:3]
    for op in reversed(ops) if reverse else ops:
        if reverse:
            yield op
        a = op.axis
        if op.kind == "t":
            v = amount[row[id(op)]] if op.joint >= 0 else xs[op.param]
            if reverse:
                M[a, 3] += v
            else:
                np.multiply(lines[a], v, out=ti)
                shift += ti
        else:
            if op.joint >= 0:
                c, s = cos[row[id(op)]], sin[row[id(op)]]
            else:
                c, s = math.cos(xs[op.param]), math.sin(xs[op.param])
            i, j = PAIRS[a]
            Mi, Mj = lines[i], lines[j]
            np.multiply(Mj, s, out=ti)
            np.multiply(Mi, s, out=tj)
            Mi *= c
            Mj *= c
            if reverse:
                Mi -= ti
                Mj += tj
            else:
                Mi += ti
                Mj -= tj
        if not reverse:
            yield op


def frames(start: np.ndarray, m: int) -> np.ndarray:
    """The 4x4 (or 3x4) transform start for m poses, (3, 4, m), ready to walk."""
    M = np.empty((3, 4, m))
    M[:] = np.asarray(start, dtype=float)[:3, :, None]
    return M


def split(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R (m, 3, 3) with the axes as columns, o (m, 3)) of frames M (3, 4, m)."""
    return np.ascontiguousarray(M[:, :3].transpose(2, 0, 1)), np.ascontiguousarray(M[:, 3].T)
