"""Lower bounds on a campaign's time: its motion (a minimum spanning tree of the move times), the
settling the simulated arm's ringing forces before a reading can pass the tracker's check, and
the re-aiming of the tracker's one beam between the readings of a pose."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .planning import move_time
from .tracker.sim import (
    INACCURATE_SPREAD,
    POINT_S,
    SETTLE_AMPLITUDE_MM,
    SETTLE_HZ,
    SETTLE_TAU_S,
)


def spanning_tree_weight(D: np.ndarray) -> float:
    """Weight of a minimum spanning tree of the complete graph with symmetric weights D (Prim)."""
    return _spanning_tree(D)[0]


def _spanning_tree(D: np.ndarray) -> tuple[float, np.ndarray]:
    """A minimum spanning tree's weight and each node's degree in it (Prim)."""
    n = len(D)
    degree = np.zeros(n, dtype=int)
    if n < 2:
        return 0.0, degree
    inside = np.zeros(n, dtype=bool)
    inside[0] = True
    reach = D[0].astype(float).copy()  # cheapest edge from the tree to each node
    via = np.zeros(n, dtype=int)  # the tree node that edge comes from
    total = 0.0
    for _ in range(n - 1):
        j = int(np.argmin(np.where(inside, np.inf, reach)))
        total += float(reach[j])
        degree[j] += 1
        degree[via[j]] += 1
        inside[j] = True
        closer = D[j] < reach
        reach = np.where(closer, D[j], reach)
        via = np.where(closer, j, via)
    return total, degree


# Subgradient steps of the Held-Karp bound: every step's bound is valid, the best is kept
HELD_KARP_STEPS = 300


def path_lower_bound(D: np.ndarray, steps: int = HELD_KARP_STEPS) -> float:
    """Weight no path from node 0 through every node of the symmetric graph D can beat: the
    Held-Karp (1-tree) bound, never below the minimum spanning tree's.

    A dummy node joined to node 0 (that edge forced) and at no cost to every other node turns
    each such path into a tour of the same weight. Adding pi_i + pi_j to each edge adds
    2 sum(pi) to every tour (each node has degree 2 in it); a tour with the dummy's edges taken
    out is a spanning tree of the others, so the minimum spanning tree of the others plus the
    dummy's two cheapest edges, less 2 sum(pi), is at most any tour's weight, whatever pi. pi
    follows the degrees' excess (subgradient steps); pi = 0, the first, gives the spanning
    tree's bound.
    """
    n = len(D)
    if n < 3:
        return spanning_tree_weight(D)
    W = np.minimum(D, D.T).astype(float)  # the cheaper direction: still a lower bound
    scale = float(W.max()) or 1.0
    pi = np.zeros(n)
    best = -np.inf
    step = 0.01 * scale
    for _ in range(steps):
        tree, degree = _spanning_tree(W + pi[:, None] + pi[None, :])
        # the dummy: its forced edge to node 0 and its cheapest other (weight 0 + pi_j)
        j = 1 + int(np.argmin(pi[1:]))
        degree[0] += 1
        degree[j] += 1
        bound = tree + pi[0] + pi[j] - 2.0 * pi.sum()
        best = max(best, bound)
        excess = degree - 2
        if not excess.any():
            break  # the 1-tree is a tour: the bound is the shortest path
        pi += step * excess
        step *= 0.98
    return float(best)


def motion_lower_bound(q, start, speeds=None) -> float:
    """Seconds of motion no order of visiting the poses q (m, n) rad from `start` can beat.

    Any such visit is a path from start through every pose: its move time is at least the
    path's Held-Karp bound on the move-time graph (path_lower_bound), itself at least a minimum
    spanning tree's.
    """
    nodes = np.vstack([np.asarray(start, dtype=float)[None], np.asarray(q, dtype=float)])
    return path_lower_bound(move_time(nodes[:, None], nodes[None], speeds))


def aiming_lower_bound(readings: int, poses: int, point_s: float = POINT_S) -> float:
    """Seconds of aiming no procedure can overlap: one beam reads a pose's SMRs one after another,
    all after the arm has settled, and between two readings the head moves and locks (point_s
    each, the simulated tracker's POINT); only the pose's first SMR may be pointed at while the
    arm still moves."""
    return max(0, int(readings) - int(poses)) * float(point_s)


@dataclass(frozen=True)
class Ringing:
    """The flange's ringing after a move, as the simulated tracker sees it (mm, s, Hz)."""

    amplitude_mm: float = SETTLE_AMPLITUDE_MM
    tau_s: float = SETTLE_TAU_S
    hz: float = SETTLE_HZ

    def at(self, t) -> np.ndarray:
        """Displacement (mm) along the ringing direction t seconds after arrival."""
        t = np.asarray(t, dtype=float)
        return self.amplitude_mm * np.exp(-t / self.tau_s) * np.sin(2 * np.pi * self.hz * t)


@dataclass(frozen=True)
class Settling:
    """Per pose: the earliest start (s after arrival) of a reading that can pass, and the ringing's
    shift of that reading's mean (mm)."""

    earliest_s: np.ndarray
    mean_shift_mm: np.ndarray


def settling_lower_bound(
    sigma_mm, samples: int, rate_hz: float, ringing: Ringing | None = None, step_s: float = 1e-3
) -> Settling:
    """For readings of `samples` samples at rate_hz on SMRs whose noise is sigma_mm (per pose,
    the largest of its SMRs'), the earliest start after arrival the tracker can accept.

    The tracker calls a reading inaccurate when a coordinate's sample spread exceeds
    INACCURATE_SPREAD sigma. Whatever the ringing's direction, one coordinate carries at least
    1/sqrt(3) of it, and the noise only adds to the spread; so a reading passes only if the
    ringing's spread over its window, over sqrt(3), is within INACCURATE_SPREAD sigma. The
    earliest start on a step_s grid where that holds is a lower bound on the wait.
    """
    ring = ringing or Ringing()
    sigma = np.atleast_1d(np.asarray(sigma_mm, dtype=float))
    limit = np.sqrt(3.0) * INACCURATE_SPREAD * sigma  # largest ring spread a reading can carry
    # past this the ring's envelope, hence its spread, is within every limit
    horizon = ring.tau_s * max(0.0, float(np.log(ring.amplitude_mm / limit.min())))
    starts = np.arange(0.0, horizon + step_s, step_s)
    window = starts[:, None] + np.arange(samples)[None] / rate_hz
    values = ring.at(window)
    spread = values.std(axis=1, ddof=1) if samples > 1 else np.zeros(len(starts))
    ok = spread[None, :] <= limit[:, None]  # (poses, starts)
    first = np.where(ok.any(axis=1), ok.argmax(axis=1), len(starts) - 1)
    return Settling(starts[first], np.abs(values.mean(axis=1))[first])
