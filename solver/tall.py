"""QR of a tall matrix in row blocks (TSQR): LAPACK on a whole Jacobian of 10,000 poses works out
of cache and takes 3-4x the time per row it takes on 1,000; blocks of BLOCK_ROWS rows keep the
time per row flat. Backward stable as one Householder QR is; Q may differ from it by the signs
(and, where J is rank-deficient, a rotation) of its columns, which spans and projections ignore."""

from __future__ import annotations

import numpy as np

BLOCK_ROWS = 4096


def blocked(J: np.ndarray) -> bool:
    """Whether J is tall enough to be factored in blocks (a smaller one as numpy does)."""
    return J.shape[0] > 4 * BLOCK_ROWS and J.shape[0] > 4 * J.shape[1]


def tall_qr(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reduced QR of J (N, P): Q (N, P) with orthonormal columns, R (P, P), J = Q R."""
    n = J.shape[0]
    if not blocked(J):
        return np.linalg.qr(J)
    parts = [np.linalg.qr(J[i : i + BLOCK_ROWS]) for i in range(0, n, BLOCK_ROWS)]
    Q2, R = np.linalg.qr(np.concatenate([r for _, r in parts]))
    Q = np.empty((n, Q2.shape[1]))
    k = 0
    for i, (q, r) in zip(range(0, n, BLOCK_ROWS), parts):
        Q[i : i + len(q)] = q @ Q2[k : k + len(r)]
        k += len(r)
    return Q, R


def tall_svd(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """U (N, P) and the singular values s of J's thin SVD; a tall J through tall_qr, its R's SVD
    rotating Q."""
    if not blocked(J):
        U, s, _ = np.linalg.svd(J, full_matrices=False)
        return U, s
    Q, R = tall_qr(J)
    U, s, _ = np.linalg.svd(R)
    return Q @ U, s
