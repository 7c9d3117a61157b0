"""The direction of each joint's last motion before a pose: from the joints the arm came from
where the data gives them (prev_q), else from the order the poses were visited."""

from __future__ import annotations

import numpy as np

# A file sorted by a joint after the fact: that joint only rises (or only falls) down its rows. A
# plan of this many poses rarely does (a sweep may, and then that joint's backlash, always
# approached from one side, does not show either).
SORTED_MIN_POSES = 10


def visit_order(time_s: np.ndarray | None, m: int) -> np.ndarray:
    """Pose indices in the order visited: by each pose's first reading time, else the file order.

    A pose without any time (or data without times) leaves the file order in force, since the
    times cannot place it.
    """
    if time_s is None:
        return np.arange(m)
    t = np.asarray(time_s, dtype=float).reshape(m, -1)
    ok = np.isfinite(t).any(axis=1)
    if not ok.all():
        return np.arange(m)
    return np.argsort(np.nanmin(t, axis=1), kind="stable")


def last_motion(
    q: np.ndarray, time_s: np.ndarray | None = None, prev_q: np.ndarray | None = None
) -> np.ndarray:
    """Per pose and joint (m, n): +1 or -1, the sign of the joint's last move before the pose.

    prev_q (m, n) rad, NaN rows where not given, are the joints the arm came from: where given,
    they decide (a file split or reordered keeps its approach directions). Elsewhere, and for a
    joint that did not move from prev_q, the visit order does: a joint that did not move keeps
    the direction of its previous move; before its first move (the first pose visited) the
    direction is unknown, 0.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    m = q.shape[0]
    order = visit_order(time_s, m)
    seq = np.zeros_like(q)
    seq[1:] = np.sign(np.diff(q[order], axis=0))
    # each joint's last nonzero step so far (row 0's zero before any): a forward fill
    last = np.maximum.accumulate(np.where(seq != 0, np.arange(m)[:, None], 0), axis=0)
    seq = np.take_along_axis(seq, last, axis=0)
    out = np.empty_like(seq)
    out[order] = seq
    if prev_q is not None:
        step = np.sign(q - np.asarray(prev_q, dtype=float))  # NaN where not given
        given = np.isfinite(step) & (step != 0)
        out = np.where(given, step, out)
    return out


def ordered_by_rows(time_s: np.ndarray | None, prev_q: np.ndarray | None, m: int) -> int:
    """How many of m poses take the direction of their joints' last motion from the file order:
    those without prev_q when time_s does not order every pose (visit_order); the first row's
    (no motion before it) does not count."""
    if m < 2:
        return 0
    if (
        time_s is not None
        and np.isfinite(np.asarray(time_s, dtype=float)).reshape(m, -1).any(axis=1).all()
    ):
        return 0  # the times order every pose
    without = (
        np.ones(m, dtype=bool)
        if prev_q is None
        else ~np.isfinite(np.asarray(prev_q, dtype=float)).all(axis=1)
    )
    return int(without[1:].sum())


def sorted_joint(q: np.ndarray) -> tuple[int, int] | None:
    """The first joint (index, +1 rising, -1 falling) whose value only rises or only falls over
    the poses q (m, n) in file order, when m >= SORTED_MIN_POSES; None when none does."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if len(q) < SORTED_MIN_POSES:
        return None
    step = np.diff(q, axis=0)
    for j in range(q.shape[1]):
        if np.ptp(q[:, j]) > 0:
            if np.all(step[:, j] >= 0):
                return j, 1
            if np.all(step[:, j] <= 0):
                return j, -1
    return None
