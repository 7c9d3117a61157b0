"""A rigid step in the order the poses were visited: a tracker bumped mid-campaign, in data whose
readings carry no time (the diagnosis fits a base shift only against time_s).

Each pose's mean residual over its SMRs is scanned for the split (EDGE_POSES at least on either
side) whose step in its mean explains most of their scatter (three coordinates, each against its
own remaining variance). The step is judged against the same scan on the poses reordered at
random: a pose-dependent error the model lacks is blind to the order and gives no step beyond
them. A plan visited in joint-space order (a grid, a travelling-salesman tour) makes such an error
follow the order too: the step is said only where the residuals, once it is removed, no longer
follow each other from pose to pose (their lag-1 autocorrelation below WHITE_LAG1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .selection import EDGE_POSES

REORDERINGS = 999  # the scan on random reorderings: a step beyond every one is p = 0.001
# the remainder's lag-1 autocorrelation: a random visit order leaves about -0.25 to 0 (the real
# IRB 120 -0.19, bumped -0.25; the real QKM -0.02), the real UR5's grid order 0.43-0.45
WHITE_LAG1 = 0.2
# smaller steps are the tracker's noise to a user (a clean simulated campaign: 0.008 mm at p = 0.001)
MIN_FLOORS = 2.0
SEED = 20261207  # the reorderings are drawn the same every time: one verdict per campaign


@dataclass(frozen=True)
class OrderStep:
    """The poses after a split in the visit order, off the model together: where, how much."""

    first_after: int  # pose index of the first pose after the step
    before: int  # poses before it
    after: int  # poses from it on
    shift_mm: np.ndarray  # (3,) their mean residual minus the others' (prediction - reading)
    p_value: float  # the share of reorderings whose best step explains as much


def _best_step(x: np.ndarray) -> tuple[float, int]:
    """The largest step statistic over the splits of pose means x (m, 3), and its split."""
    m = len(x)
    k = np.arange(EDGE_POSES, m - EDGE_POSES + 1)
    c = np.cumsum(x, axis=0)
    diff = (c[-1] - c[k - 1]) / (m - k)[:, None] - c[k - 1] / k[:, None]
    explained = (k * (m - k) / m)[:, None] * diff**2
    total = np.sum((x - x.mean(axis=0)) ** 2, axis=0)
    left = np.maximum(total[None] - explained, 1e-30) / (m - 2)
    t = np.sum(explained / left, axis=1)
    j = int(np.argmax(t))
    return float(t[j]), int(k[j])


def order_step(resid: np.ndarray, order: np.ndarray, floor_mm: float | None) -> OrderStep | None:
    """The step in visit order `order` of the residuals (m, K, 3) (prediction - reading, NaN where
    missing) beyond every random reordering, in residuals that are otherwise unordered, and of
    MIN_FLOORS x the noise floor (floor_mm, None: unknown) at least; None when there is none."""
    r = np.asarray(resid, dtype=float)
    seen = np.all(np.isfinite(r), axis=-1)
    order = np.asarray(order)[seen[np.asarray(order)].any(axis=1)]
    m = len(order)
    if m < 4 * EDGE_POSES:
        return None
    x = np.where(seen[..., None], r, 0.0)[order].sum(axis=1) / seen[order].sum(axis=1)[:, None]
    t, k = _best_step(x)
    shift = x[k:].mean(axis=0) - x[:k].mean(axis=0)
    if floor_mm is not None and not np.linalg.norm(shift) >= MIN_FLOORS * floor_mm:
        return None
    rest = x.copy()
    rest[:k] -= rest[:k].mean(axis=0)
    rest[k:] -= rest[k:].mean(axis=0)
    lag1 = float(np.sum(rest[1:] * rest[:-1]) / np.sum(rest * rest))
    if not lag1 < WHITE_LAG1:
        return None
    rng = np.random.default_rng(SEED)
    beaten = sum(_best_step(x[rng.permutation(m)])[0] >= t for _ in range(REORDERINGS))
    if beaten:
        return None
    return OrderStep(int(order[k]), k, m - k, shift, 1.0 / (1 + REORDERINGS))
