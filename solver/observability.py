"""Observability of a pose set from its identification Jacobian, and optimal choice of poses.

Inputs are per-pose Jacobian blocks J (N, rows, P): for each candidate pose, the derivatives of
its measured coordinates with respect to the P identifiable parameters.
"""

from __future__ import annotations

import numpy as np

from .finite import finite

# Relative gain an exchange must bring to be taken: stops cycling between equal designs.
EXCHANGE_TOL = 1e-9
MAX_SWEEPS = 50
# Ridge (relative to the mean information per parameter) that keeps log det finite while the
# greedy start has fewer rows than parameters; far below any full-rank design's eigenvalues.
RIDGE = 1e-9


def unit_columns(J_per_pose: np.ndarray) -> np.ndarray:
    """J scaled so every parameter column has unit norm over all poses (mm and rad comparable)."""
    J = np.asarray(J_per_pose, dtype=float)
    norms = np.sqrt(np.einsum("nrp,nrp->p", J, J))
    return J / np.where(norms > 0, norms, 1.0)


def information(J_per_pose: np.ndarray) -> np.ndarray:
    """Per-pose information matrices J_i' J_i, shape (N, P, P)."""
    return np.einsum("nrp,nrq->npq", J_per_pose, J_per_pose)


def _log_det(M: np.ndarray) -> np.ndarray:
    sign, ld = np.linalg.slogdet(finite(M, "the information matrix"))
    return np.where(sign > 0, ld, -np.inf)


def _o5(M: np.ndarray) -> np.ndarray:
    # eigenvalues of J'J are the squared singular values: sigma_min^2 / sigma_max
    lam = np.linalg.eigvalsh(finite(M, "the information matrix"))
    return np.clip(lam[..., 0], 0.0, None) / np.sqrt(lam[..., -1])


CRITERIA = {"D": _log_det, "O5": _o5}


def _scores(criterion: str, M: np.ndarray, J: np.ndarray, A: np.ndarray) -> np.ndarray:
    """The criterion of M + J_j'J_j for every pose j."""
    if criterion == "O5":
        return _o5(M + A)
    # determinant lemma: log det(M + J'J) = log det M + log det(I + J M^-1 J'), rows << P
    G = J @ np.linalg.inv(finite(M, "the information matrix"))
    S = np.eye(J.shape[1]) + G @ J.transpose(0, 2, 1)
    return _log_det(M[None])[0] + _log_det(S)


def select_poses(J_per_pose: np.ndarray, k: int, criterion: str = "D", progress=None) -> np.ndarray:
    """Sorted indices of k poses maximising "D" (log det J'J) or "O5": greedy + Fedorov exchange;
    progress(fraction) after each greedy pick and exchange sweep, if given."""
    # O5 = sigma_min^2 / sigma_max, Nahvi & Nahvi's noise-amplification index. Columns get unit
    # norm over all candidates, so the choice does not depend on the parameters' units.
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {sorted(CRITERIA)}, not {criterion!r}")
    J = unit_columns(J_per_pose)
    A = information(J)
    N, P = A.shape[:2]
    if not 0 < k <= N:
        raise ValueError(f"cannot choose {k} of {N} poses")
    M = RIDGE * np.trace(A.sum(axis=0)) / (N * P) * np.eye(P)
    free = np.ones(N, dtype=bool)
    chosen = []
    # The greedy start is always D: O5 stays zero until the design has full rank, so it
    # cannot tell the first poses apart.
    for _ in range(k):
        score = np.where(free, _scores("D", M, J, A), -np.inf)
        j = int(np.argmax(score))
        chosen.append(j)
        free[j] = False
        M = M + A[j]
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
            rest = M - A[chosen[pos]]
            score = np.where(free, _scores(criterion, rest, J, A), -np.inf)
            j = int(np.argmax(score))
            if score[j] > best + EXCHANGE_TOL * max(1.0, abs(best)):
                free[chosen[pos]], free[j] = True, False
                chosen[pos], M, best = j, rest + A[j], float(score[j])
                improved = True
        if not improved:
            break
    return np.sort(np.array(chosen))


def observability_indices(J: np.ndarray) -> dict[str, float]:
    """log det(J'J), condition number, O1 (geometric mean of singular values / sqrt(rows)), O5."""
    # J is (rows, P) or per pose (n, rows, P), used as given: scale its columns over the
    # candidate set (unit_columns) before comparing pose sets.
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
