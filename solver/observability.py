"""Observability of a pose set from its identification Jacobian, and optimal choice of poses.

Inputs are per-pose Jacobian blocks: for each candidate pose, the derivatives of its measured
coordinates with respect to the P identifiable parameters, either dense (N, rows, P) or as
PoseJacobians, which leaves out the zeros of each SMR's rows in the other SMRs' coordinates so
that memory grows linearly with the SMRs (the dense form grows with their square).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from .finite import finite

# Relative gain an exchange must bring to be taken: stops cycling between equal designs.
EXCHANGE_TOL = 1e-9
MAX_SWEEPS = 50
# Ridge (relative to the mean information per parameter) that keeps log det finite while the
# greedy start has fewer rows than parameters; far below any full-rank design's eigenvalues.
RIDGE = 1e-9
# Dense Jacobian rows built at once: by the QR of a stacked Jacobian, and by the scores of a
# block of candidate poses. Memory then grows with the parameters (linear in the SMRs), not
# with poses x SMRs x parameters.
BLOCK_ROWS = 720
SCORE_ROWS = 2048


@dataclass(frozen=True)
class PoseJacobians:
    """Per-pose Jacobians without their zeros: memory linear in the SMRs.

    SMR k's rows at pose i are shared[i, k] (r, C) in the columns every reading moves with
    (geometry, base) and own[i, k] (r, w) in the SMR's own coordinates, zero in the other
    SMRs'; own_free (K, w) marks the own columns identified (the others are zero and left out).
    The dense Jacobian's columns are the C shared ones, then each SMR's free own ones in turn.
    """

    shared: np.ndarray  # (N, K, r, C)
    own: np.ndarray  # (N, K, r, w)
    own_free: np.ndarray  # (K, w) bool

    @classmethod
    def dense_form(cls, J) -> PoseJacobians:
        """Dense per-pose blocks (N, rows, P) as one shared block of every column."""
        J = np.asarray(J, dtype=float)
        n, r, _ = J.shape
        return cls(J[:, None], np.zeros((n, 1, r, 0)), np.zeros((1, 0), dtype=bool))

    def __len__(self) -> int:
        return len(self.shared)

    def __getitem__(self, idx) -> PoseJacobians:
        return PoseJacobians(self.shared[idx], self.own[idx], self.own_free)

    @property
    def n_params(self) -> int:
        return self.shared.shape[-1] + int(self.own_free.sum())

    @property
    def rows_per_pose(self) -> int:
        return self.shared.shape[1] * self.shared.shape[2]

    def dense(self) -> np.ndarray:
        """The dense per-pose Jacobians (N, K x r, P): for small sets and tests."""
        n, K, r, C = self.shared.shape
        out = np.zeros((n, K, r, self.n_params))
        out[..., :C] = self.shared
        at = C
        for k in range(K):
            cols = np.flatnonzero(self.own_free[k])
            out[:, k, :, at : at + len(cols)] = self.own[:, k][..., cols]
            at += len(cols)
        return out.reshape(n, K * r, -1)

    def dense_blocks(self):
        """The stacked dense Jacobian's rows, about BLOCK_ROWS at a time."""
        step = max(1, BLOCK_ROWS // self.rows_per_pose)
        for start in range(0, len(self), step):
            yield self[start : start + step].dense().reshape(-1, self.n_params)


def _blocks(J) -> PoseJacobians:
    return J if isinstance(J, PoseJacobians) else PoseJacobians.dense_form(J)


def stacked_r(blocks, n_params: int) -> np.ndarray:
    """R of the QR of the blocks' rows stacked (R'R = J'J), factored a block at a time."""
    R = np.zeros((0, n_params))
    for J in blocks:
        # numpy's stubs type every qr() as the (Q, R) pair; mode="r" returns R alone
        R = cast(
            np.ndarray,
            np.linalg.qr(finite(np.vstack([R, J]), "the identification Jacobian"), mode="r"),
        )
    return R


def unit_columns(J_per_pose):
    """J scaled so every parameter column has unit norm over all poses (mm and rad comparable)."""
    if not isinstance(J_per_pose, PoseJacobians):
        J = np.asarray(J_per_pose, dtype=float)
        norms = np.sqrt(np.einsum("nrp,nrp->p", J, J))
        return J / np.where(norms > 0, norms, 1.0)
    pj = J_per_pose
    shared = np.sqrt(np.einsum("nkrc,nkrc->c", pj.shared, pj.shared))
    own = np.sqrt(np.einsum("nkrw,nkrw->kw", pj.own, pj.own))
    return PoseJacobians(
        pj.shared / np.where(shared > 0, shared, 1.0),
        pj.own / np.where(own > 0, own, 1.0)[None, :, None, :],
        pj.own_free,
    )


def information(J_per_pose: np.ndarray) -> np.ndarray:
    """Per-pose information matrices J_i' J_i, shape (N, P, P), of dense per-pose blocks."""
    return np.einsum("nrp,nrq->npq", J_per_pose, J_per_pose)


def _log_det(M: np.ndarray) -> np.ndarray:
    sign, ld = np.linalg.slogdet(finite(M, "the information matrix"))
    return np.where(sign > 0, ld, -np.inf)


def _o5(M: np.ndarray) -> np.ndarray:
    # eigenvalues of J'J are the squared singular values: sigma_min^2 / sigma_max
    lam = np.linalg.eigvalsh(finite(M, "the information matrix"))
    return np.clip(lam[..., 0], 0.0, None) / np.sqrt(lam[..., -1])


CRITERIA = {"D": _log_det, "O5": _o5}


def _scores(criterion: str, M: np.ndarray, rows, n: int, per_pose: int) -> np.ndarray:
    """The criterion of M + J_j'J_j for each of the n poses, a block of poses at a time (each
    block's dense rows, rows(start, stop), about SCORE_ROWS: memory linear in the SMRs)."""
    step = max(1, SCORE_ROWS // per_pose)
    if criterion == "D":
        # determinant lemma: log det(M + J'J) = log det M + log det(I + J M^-1 J'), rows << P
        Minv = np.linalg.inv(finite(M, "the information matrix"))
        base = _log_det(M[None])[0]
    out = []
    for start in range(0, n, step):
        Jc = rows(start, start + step)
        if criterion == "O5":
            out.append(_o5(M + information(Jc)))
        else:
            S = np.eye(Jc.shape[1]) + (Jc @ Minv) @ Jc.transpose(0, 2, 1)
            out.append(base + _log_det(S))
    return np.concatenate(out)


def select_poses(J_per_pose, k: int, criterion: str = "D", progress=None) -> np.ndarray:
    """Sorted indices of k poses maximising "D" (log det J'J) or "O5": greedy + Fedorov exchange;
    progress(fraction) after each greedy pick and exchange sweep, if given."""
    # O5 = sigma_min^2 / sigma_max, Nahvi & Nahvi's noise-amplification index. Columns get unit
    # norm over all candidates, so the choice does not depend on the parameters' units.
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {sorted(CRITERIA)}, not {criterion!r}")
    J = unit_columns(_blocks(J_per_pose))
    N, P = len(J), J.n_params
    if not 0 < k <= N:
        raise ValueError(f"cannot choose {k} of {N} poses")
    # trace of the summed information: the squared norms of all the columns
    trace = float(np.sum(J.shared**2) + np.sum(J.own**2))
    M = RIDGE * trace / (N * P) * np.eye(P)
    # Few SMRs: the dense rows cost at most twice the compact ones (still linear in the SMRs),
    # so they are built once rather than for every score.
    whole = J.dense() if P <= 2 * (J.shared.shape[-1] + J.own.shape[-1]) else None

    def rows(start: int, stop: int) -> np.ndarray:
        return whole[start:stop] if whole is not None else J[start:stop].dense()

    def scores(criterion: str, M: np.ndarray) -> np.ndarray:
        return np.where(free, _scores(criterion, M, rows, N, J.rows_per_pose), -np.inf)

    def pose_information(j: int) -> np.ndarray:
        return information(rows(j, j + 1))[0]

    free = np.ones(N, dtype=bool)
    chosen = []
    # The greedy start is always D: O5 stays zero until the design has full rank, so it
    # cannot tell the first poses apart.
    for _ in range(k):
        j = int(np.argmax(scores("D", M)))
        chosen.append(j)
        free[j] = False
        M = M + pose_information(j)
        if progress is not None:
            progress(0.5 * len(chosen) / k)
    best = float(CRITERIA[criterion](M[None])[0])
    for sweep in range(MAX_SWEEPS):
        # The exchange stops when a sweep finds nothing better; until then, each sweep closes
        # half of what is left, so the fraction rises without knowing how many will come.
        if progress is not None:
            progress(1.0 - 0.5 ** (sweep + 2))
        improved = False
        for pos in range(k):
            rest = M - pose_information(chosen[pos])
            score = scores(criterion, rest)
            j = int(np.argmax(score))
            if score[j] > best + EXCHANGE_TOL * max(1.0, abs(best)):
                free[chosen[pos]], free[j] = True, False
                chosen[pos], M, best = j, rest + pose_information(j), float(score[j])
                improved = True
        if not improved:
            break
    return np.sort(np.array(chosen))


def observability_indices(J) -> dict[str, float]:
    """log det(J'J), condition number, O1 (geometric mean of singular values / sqrt(rows)), O5."""
    # J is (rows, P), per pose (n, rows, P) or PoseJacobians, used as given: scale its columns
    # over the candidate set (unit_columns) before comparing pose sets.
    if isinstance(J, PoseJacobians):
        # R'R = J'J: R has J's singular values, and is factored a block of poses at a time
        rows, P = len(J) * J.rows_per_pose, J.n_params
        J = stacked_r(J.dense_blocks(), P)
    else:
        J = np.asarray(J, dtype=float)
        J = J.reshape(-1, J.shape[-1])
        rows, P = J.shape
    s = np.zeros(P)
    sv = np.linalg.svd(finite(J, "the identification Jacobian"), compute_uv=False)
    s[: sv.size] = sv
    with np.errstate(divide="ignore"):
        logs = np.log(s)
    return {
        "log_det": float(2.0 * logs.sum()),
        "condition": float(s[0] / s[-1]) if s[-1] > 0 else float("inf"),
        "O1": float(np.exp(logs.mean()) / np.sqrt(rows)),
        "O5": float(s[-1] ** 2 / s[0]) if s[0] > 0 else 0.0,
    }
