"""Which parameters the data can identify: redundancy with the base, the SMRs or each other."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kinematics import Layout, predict_with_jacobian

# A column whose part outside the span of the columns kept before it is below this fraction of
# its norm is redundant: exact redundancies sit near 1e-12, weak but real ones far above.
STRUCTURAL_TOL = 1e-6
# Refuse data whose Jacobi-scaled Jacobian is worse conditioned than this.
MAX_CONDITION = 1e7
STRUCTURAL_POSES = 240


class NotIdentifiable(ValueError):
    """The data cannot identify the model; the message names what cannot be identified."""


@dataclass
class Identifiability:
    """Parameters held fixed (with the reason) and the conditioning of the rest."""

    free: np.ndarray  # bool (P,)
    fixed: dict[str, str]  # name -> why it is held
    condition: float


def preference_order(layout: Layout) -> list[int]:
    """Columns in the order they should be kept: base, SMRs, then the joints.

    Keeping the base and SMR positions first hands the redundancy to joint 1 (theta, d) and the
    last joint, as calibration engineers expect; a parallel joint's d goes last because Hayati's
    beta replaces it.
    """
    names = layout.names()
    geo = list(range(layout.n_geo))
    late = [i for i in geo if names[i].startswith("d") and
            layout.robot.parallel[int(names[i][1:]) - 1]]
    early = [i for i in geo if i not in late]
    base = list(range(layout.base_slice.start, layout.base_slice.stop))
    tgt = list(range(layout.target_slice.start, layout.target_slice.stop))
    return base + tgt + early + late


def _greedy_span(R: np.ndarray, order, candidates: np.ndarray, tol: float):
    """Walk columns of R in order; keep those adding a direction above tol, return kept mask and residuals."""
    P = R.shape[1]
    basis = np.zeros((R.shape[0], 0))
    kept = np.zeros(P, dtype=bool)
    rel = np.ones(P)
    for j in order:
        if not candidates[j]:
            continue
        col = R[:, j]
        norm = np.linalg.norm(col)
        if norm == 0.0:
            rel[j] = 0.0
            continue
        resid = col - basis @ (basis.T @ col)
        resid = resid - basis @ (basis.T @ resid)  # second pass keeps Gram-Schmidt orthogonal
        rel[j] = np.linalg.norm(resid) / norm
        if rel[j] > tol:
            basis = np.column_stack([basis, resid / np.linalg.norm(resid)])
            kept[j] = True
    return kept, rel


def _explain(R: np.ndarray, j: int, kept: np.ndarray, names) -> str:
    """Name the kept parameters that the redundant column j is mostly made of."""
    idx = np.flatnonzero(kept)
    A = R[:, idx] / np.linalg.norm(R[:, idx], axis=0)
    coef, *_ = np.linalg.lstsq(A, R[:, j] / np.linalg.norm(R[:, j]), rcond=None)
    top = idx[np.argsort(-np.abs(coef))[:3]]
    top = [names[i] for i, c in zip(top, np.sort(-np.abs(coef))[:3]) if -c > 0.05]
    return "redundant with " + ", ".join(top) if top else "no effect on the measured SMRs"


def jacobian_rows(layout: Layout, x, q, mask) -> np.ndarray:
    """Identification Jacobian rows (readings x 3, P) of the measured readings."""
    _, J, _ = predict_with_jacobian(layout, x, q)
    return J[mask].reshape(-1, layout.n_params)


def structural(layout: Layout, x, candidates: np.ndarray, rows_fn=None,
               rng_seed: int = 0) -> Identifiability:
    """Redundancies of the model itself, found on a rich set of random poses within the limits.

    rows_fn(points, J) turns the point Jacobian into the method's residual Jacobian rows
    (default: every SMR coordinate is a residual).
    """
    rng = np.random.default_rng(rng_seed)
    robot = layout.robot
    q = rng.uniform(robot.lower, robot.upper, size=(STRUCTURAL_POSES, robot.n_joints))
    p, J, _ = predict_with_jacobian(layout, x, q)
    J = J.reshape(-1, layout.n_params) if rows_fn is None else rows_fn(p, J)
    R = np.linalg.qr(J, mode="r")
    kept, _ = _greedy_span(R, preference_order(layout), candidates, STRUCTURAL_TOL)
    names = layout.names()
    fixed = {names[j]: _explain(R, j, kept, names)
             for j in np.flatnonzero(candidates & ~kept)}
    return Identifiability(kept, fixed, condition_number(J[:, kept]))


def condition_number(J: np.ndarray) -> float:
    """Condition number of J after scaling every column to unit norm."""
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    s = np.linalg.svd(J / norms, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def check_data(J: np.ndarray, free: np.ndarray, names, n_poses: int) -> float:
    """Condition number of the data's Jacobian on the free parameters; refuse data that cannot identify them."""
    idx = np.flatnonzero(free)
    Jf = J[:, idx]
    if Jf.shape[0] < len(idx):
        raise NotIdentifiable(
            f"{n_poses} poses give {Jf.shape[0]} equations for {len(idx)} parameters: "
            f"measure at least {int(np.ceil(len(idx) / max(1, J.shape[0] // max(n_poses, 1))))} poses")
    norms = np.linalg.norm(Jf, axis=0)
    dead = [names[i] for i, n in zip(idx, norms) if n == 0]
    if dead:
        raise NotIdentifiable("the data does not move with: " + ", ".join(dead))
    U, s, Vt = np.linalg.svd(Jf / norms, full_matrices=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    if cond > MAX_CONDITION:
        weak = Vt[s < s[0] / MAX_CONDITION]
        score = np.max(np.abs(weak), axis=0)
        worst = [names[idx[i]] for i in np.argsort(-score)[:4] if score[i] > 0.2]
        raise NotIdentifiable(
            f"the poses cannot separate {', '.join(worst)} (condition number {cond:.3g}): "
            "measure more poses, spread over the joint ranges")
    return cond
