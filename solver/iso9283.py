"""ISO 9283:1998 pose characteristics from attained positions: accuracy and repeatability of
positioning and of distance, and the standard cube's five test points.

Attained positions come as (p, n, 3): p test points, each reached n times (cycles x approach
directions); commanded positions as (p, 3). Units are whatever the caller uses (mm at the edges).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# 6.8: P2..P5 lie on the measuring plane's diagonals, this fraction of a diagonal from its corners
CORNER_FRACTION = 0.1


@dataclass
class PositionFigures:
    """Per test point: AP components (p, 3), AP (p,), RP (p,), barycentre (p, 3), l_bar, S_l."""

    ap_xyz: np.ndarray
    ap: np.ndarray
    rp: np.ndarray
    barycentre: np.ndarray
    l_bar: np.ndarray
    s_l: np.ndarray


@dataclass
class DistanceFigures:
    """Per pair of test points (i, j): AD (k,), its components (k, 3), and RD (k,)."""

    pairs: list[tuple[int, int]]
    ad: np.ndarray
    ad_xyz: np.ndarray
    rd: np.ndarray


def position_figures(attained, commanded) -> PositionFigures:
    """7.2 pose accuracy, position part: AP = |x_bar - x_c| with x_bar the barycentre of the n
    attained positions; 7.2 pose repeatability, position part: RP = l_bar + 3 S_l, l_j the
    distance of attained position j to the barycentre, S_l their standard deviation (n - 1)."""
    a = np.asarray(attained, dtype=float)
    c = np.asarray(commanded, dtype=float)
    if a.ndim != 3 or a.shape[2] != 3 or c.shape != (a.shape[0], 3):
        raise ValueError("attained must be (p, n, 3) and commanded (p, 3)")
    if a.shape[1] < 2:
        raise ValueError("repeatability needs at least two attained positions per point")
    bary = a.mean(axis=1)
    ap_xyz = bary - c
    dist = np.linalg.norm(a - bary[:, None], axis=-1)
    l_bar = dist.mean(axis=1)
    s_l = dist.std(axis=1, ddof=1)
    return PositionFigures(
        ap_xyz, np.linalg.norm(ap_xyz, axis=-1), l_bar + 3 * s_l, bary, l_bar, s_l
    )


def multidirectional_variation(attained, direction) -> np.ndarray:
    """7.2 (multi-directional) pose accuracy variation, position part: vAP per point (p,), the
    largest distance between the barycentres of the positions reached from each approach
    direction; direction (n,) labels each of the n attained positions."""
    a = np.asarray(attained, dtype=float)
    d = np.asarray(direction)
    labels = np.unique(d)
    bary = np.stack([a[:, d == h].mean(axis=1) for h in labels], axis=1)  # (p, h, 3)
    gaps = np.linalg.norm(bary[:, :, None] - bary[:, None], axis=-1)
    return gaps.max(axis=(1, 2))


def distance_figures(attained, commanded, pairs) -> DistanceFigures:
    """7.3 distance accuracy: AD = D_bar - D_c, D_j the attained distance between the two
    points in cycle j, D_c the commanded one (components likewise, per axis); 7.3 distance
    repeatability: RD = 3 sqrt(sum (D_j - D_bar)^2 / (n - 1)). Attained position j of each point
    belongs to the same cycle."""
    a = np.asarray(attained, dtype=float)
    c = np.asarray(commanded, dtype=float)
    ad, ad_xyz, rd = [], [], []
    for i, j in pairs:
        d = np.linalg.norm(a[i] - a[j], axis=-1)
        d_xyz = np.abs(a[i] - a[j])
        ad.append(d.mean() - np.linalg.norm(c[i] - c[j]))
        ad_xyz.append(d_xyz.mean(axis=0) - np.abs(c[i] - c[j]))
        rd.append(3 * d.std(ddof=1))
    return DistanceFigures(list(pairs), np.array(ad), np.array(ad_xyz), np.array(rd))


def cube_points(centre, side, rotation=None) -> np.ndarray:
    """6.8 the test cube's five points (5, 3): P1 at the cube's centre, P2..P5 on the diagonals
    of the measuring plane (the plane through two opposite edges, here the edges (-,-,-)..(-,-,+)
    and (+,+,-)..(+,+,+) in the cube's axes) at CORNER_FRACTION of the diagonal from its corners.
    rotation (3, 3) turns the cube's axes into the cell frame."""
    h = side / 2.0
    corners = np.array([[-h, -h, h], [h, h, h], [h, h, -h], [-h, -h, -h]])  # C1..C4 in order
    opposite = corners[[2, 3, 0, 1]]
    inner = corners + CORNER_FRACTION * (opposite - corners)
    local = np.vstack([np.zeros(3), inner])
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    return np.asarray(centre, dtype=float) + local @ R.T


# The standard's distance test runs between P2 and P4; the other diagonal is the same kind
CUBE_PAIRS = [(1, 3), (2, 4)]
