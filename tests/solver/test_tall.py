"""QR and SVD of tall matrices in row blocks: the factorisation numpy's would give, up to signs."""

import numpy as np

from robocal.solver import tall


def matrix(rows, cols=12, seed=0):
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(rows, cols)) * np.logspace(-4, 3, cols)  # mm- and rad-like columns
    J[:, 5] = 2.0 * J[:, 1]  # rank-deficient, as a Jacobian with a dependent column is
    return J


def test_blocked_qr_factors_a_tall_matrix(monkeypatch):
    monkeypatch.setattr(tall, "BLOCK_ROWS", 100)
    J = matrix(1234)
    assert tall.blocked(J)
    Q, R = tall.tall_qr(J)
    assert np.allclose(Q @ R, J, rtol=0, atol=1e-13 * np.abs(J).max())
    assert np.allclose(Q.T @ Q, np.eye(J.shape[1]), atol=1e-13)
    assert np.allclose(R.T @ R, J.T @ J, rtol=0, atol=1e-12 * np.abs(J.T @ J).max())
    assert np.allclose(np.triu(R), R)


def test_blocked_svd_has_the_same_values_and_projections(monkeypatch):
    monkeypatch.setattr(tall, "BLOCK_ROWS", 100)
    J = matrix(1234)
    y = np.random.default_rng(1).normal(size=len(J))
    U, s = tall.tall_svd(J)
    U0, s0, _ = np.linalg.svd(J, full_matrices=False)
    assert np.allclose(s, s0, rtol=1e-10, atol=1e-12 * s0[0])
    rank = int(np.sum(s0 > s0[0] * max(J.shape) * np.finfo(float).eps))
    assert rank == J.shape[1] - 1
    inside = np.sum((U[:, :rank].T @ y) ** 2)
    assert np.isclose(inside, np.sum((U0[:, :rank].T @ y) ** 2), rtol=1e-10)


def test_a_small_matrix_is_factored_as_numpy_does():
    J = matrix(300)
    assert not tall.blocked(J)
    assert np.array_equal(tall.tall_qr(J)[1], np.linalg.qr(J)[1])
