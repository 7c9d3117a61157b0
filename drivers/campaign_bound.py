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
    n = len(D)
    if n < 2:
        return 0.0
    inside = np.zeros(n, dtype=bool)
    inside[0] = True
    reach = D[0].astype(float).copy()  # cheapest edge from the tree to each node
    total = 0.0
    for _ in range(n - 1):
        j = int(np.argmin(np.where(inside, np.inf, reach)))
        total += float(reach[j])
        inside[j] = True
        reach = np.minimum(reach, D[j])
    return total


def motion_lower_bound(q, start, speeds=None) -> float:
    """Seconds of motion no order of visiting the poses q (m, n) rad from `start` can beat.

    Any such visit is a path through start and every pose, and a path is a spanning tree, so its
    move time is at least a minimum spanning tree's on the same move-time graph.
    """
    nodes = np.vstack([np.asarray(start, dtype=float)[None], np.asarray(q, dtype=float)])
    return spanning_tree_weight(move_time(nodes[:, None], nodes[None], speeds))


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
