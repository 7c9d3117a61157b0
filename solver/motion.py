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
        prev = np.asarray(prev_q, dtype=float)
        step = np.sign(q - prev)  # NaN where not given
        given = np.isfinite(step) & (step != 0)
        if not _timed(time_s, m) and rows_follow_prev_q(q, prev) is False:
            # the rows are not the visit order (the prev_q given do not follow their rows): a
            # pose without prev_q has no known approach, like the first visited (a shuffled
            # file's one such pose took a random row's direction: 0.63 mm off its backlash)
            out = np.where(np.isfinite(prev).all(axis=1)[:, None], out, 0.0)
        out = np.where(given, step, out)
    return out


def _timed(time_s, m: int) -> bool:
    """Whether time_s orders every one of the m poses (visit_order follows it)."""
    if time_s is None:
        return False
    return bool(np.isfinite(np.asarray(time_s, dtype=float)).reshape(m, -1).any(axis=1).all())


# prev_q equal to the row above's joints within this (rad): the file is in the order visited
FOLLOWS_RAD = 1e-6


def rows_follow_prev_q(q: np.ndarray, prev_q: np.ndarray) -> bool | None:
    """Whether the file's rows are the order visited, as its prev_q tell (each pose's prev_q the
    row above's joints, for half those given at least); None when no pose but the first gives
    them (nothing to tell by)."""
    prev = np.asarray(prev_q, dtype=float)
    have = np.isfinite(prev).all(axis=1)
    have[0] = False
    if not have.any():
        return None
    k = np.flatnonzero(have)
    follows = np.all(np.abs(prev[k] - q[k - 1]) <= FOLLOWS_RAD, axis=1)
    return bool(2 * follows.sum() >= len(k))


def ordered_by_rows(
    time_s: np.ndarray | None, prev_q: np.ndarray | None, m: int, q: np.ndarray | None = None
) -> int:
    """How many of m poses take the direction of their joints' last motion from the file order:
    those without prev_q when time_s does not order every pose (visit_order); the first row's
    (no motion before it) does not count."""
    if m < 2:
        return 0
    if _timed(time_s, m):
        return 0  # the times order every pose
    if prev_q is None:
        return m - 1
    if q is not None and rows_follow_prev_q(np.asarray(q, dtype=float), prev_q) is False:
        return 0  # the rows are not the order visited: a pose without prev_q has none (0)
    return int((~np.isfinite(np.asarray(prev_q, dtype=float)).all(axis=1))[1:].sum())


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
