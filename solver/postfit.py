"""A fit's standard errors and leave-one-pose-out residuals in two passes over its residual rows,
a block of whole poses at a time: the normal matrices first, then each pose's small blocks.

Every figure is a sum over poses (the meats) or a function of one pose's rows and the whole fit's
normal matrix (the held-out residuals, the hat matrix's diagonal blocks), so the blocks give the
same figures as the whole Jacobian at once, whose 50,000 poses would take 450,000 rows. The
second pass needs the first's inverse before its first pose, so one pass would have to keep
every row; a caller that has the normal matrices otherwise (a least-squares fit's, assembled
without its rows: fit_errors.plain_sums) hands them over, and the rows are built once.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from .guard import Holdout, held_out, holdout_inverse
from .prior import PriorTerms
from .uncertainty import (
    Rows,
    StageSums,
    bread,
    cr2_block_meat,
    hat_blocks,
    plain_from_sums,
    pose_blocks,
    stage_sums,
)

# A block holds about this many Jacobian entries (8 bytes each): 4 MiB a matrix, a handful of
# them alive at once, next to the fit's own ~100 MiB at 50,000 poses.
BLOCK_ENTRIES = 1 << 19

# Relative difference below which the covariance's inverse of the normal matrix and the held-out
# residuals' pseudo-inverse are one matrix.
SAME_INVERSE = 1e-10

# Each call yields the fit's rows again, in blocks of whole poses, blocks in pose order.
Blocks = Callable[[], Iterable[Rows]]


def poses_per_block(rows_per_pose: int, params: int) -> int:
    """Poses a block of BLOCK_ENTRIES Jacobian entries holds."""
    return max(1, BLOCK_ENTRIES // max(1, rows_per_pose * params))


@dataclass
class PostFit:
    """A fit's covariances (CR2 clustered and plain) and held-out residuals."""

    clustered: np.ndarray
    plain: np.ndarray
    holdout: Holdout
    poses: int


@dataclass
class Sums:
    """What the first pass gathers of a fit's rows: A = G'J, B = G'G and each stage's sums."""

    A: np.ndarray
    B: np.ndarray
    stages: dict[int, StageSums]


def sums(blocks: Blocks) -> Sums:
    """The first pass: the normal matrices of the stacked blocks, one block at a time."""
    A = B = None
    stages: dict[int, StageSums] = {}
    for rows in blocks():
        if not len(rows.r):
            continue
        GJ = rows.G.T @ rows.J
        GG = GJ if rows.G is rows.J else rows.G.T @ rows.G
        A, B = (GJ, GG) if A is None or B is None else (A + GJ, B + GG)
        for s, part in stage_sums(rows, GG).items():
            if s in stages:
                stages[s].add(part)
            else:
                stages[s] = part
    if A is None or B is None:
        raise ValueError("no residual rows")
    return Sums(A, B, stages)


def post_fit(
    blocks: Blocks,
    point: Callable[[Rows], np.ndarray] | None = None,
    known: Sums | None = None,
    prior: PriorTerms | None = None,
) -> PostFit:
    """The figures of uncertainty.clustered, uncertainty.plain and guard.leave_one_pose_out of
    the stacked blocks, holding one block at a time. point(rows): which rows of a block are point
    errors (default all); known: the blocks' Sums when the caller has them (the rows are then
    built once), else a first pass over the blocks takes them. prior: the geometry prior's terms
    (solver.prior) of a shrunk fit: its information in the bread (and the held-out residuals'
    fit), its scores' covariance in the meat, so the covariance is the posterior's (Bayesian:
    true changes drawn from the prior)."""
    first = known or sums(blocks)
    A, B, stages = first.A, first.B, first.stages
    if prior is not None:
        A, B = A + prior.information, B + prior.residual
    Ai = bread(A)
    C = Ai @ B @ Ai.T
    Ah = holdout_inverse(A)
    # the two inverses of a well-conditioned fit agree to rounding: one hat matrix serves both
    same = bool(np.linalg.norm(Ai - Ah) <= SAME_INVERSE * np.linalg.norm(Ai))
    meat = np.zeros_like(A) if prior is None else prior.meat.copy()
    held, stage, unsupported, poses = [], [], [], set()
    for rows in blocks():  # each pose's blocks
        if not len(rows.r):
            continue
        e = np.full(len(rows.r), np.nan)
        for _n, idx in pose_blocks(rows.pose):
            J, r = rows.J[idx], rows.r[idx]
            G = J if rows.G is rows.J else rows.G[idx]
            H = hat_blocks(J, G, Ai)
            meat += cr2_block_meat(J, G, r, H, C)
            e[idx], ok = held_out(H if same else hat_blocks(J, G, Ah), r)
            unsupported += rows.pose[idx[~ok, 0]].tolist()
        keep = np.ones(len(e), dtype=bool) if point is None else np.asarray(point(rows), bool)
        held.append(e[keep])
        stage.append(rows.stage[keep])
        poses.update(np.unique(rows.pose).tolist())
    # the stacked rows' order: stage by stage, poses in order within each
    order = np.argsort(np.concatenate(stage), kind="stable")
    residuals = np.concatenate(held)[order].reshape(-1, 3)
    holdout = Holdout(residuals, np.array(sorted(set(unsupported)), dtype=int))
    plain = plain_from_sums(Ai, stages)
    if prior is not None:
        plain += Ai @ prior.meat @ Ai.T
    return PostFit(Ai @ meat @ Ai.T, plain, holdout, len(poses))
