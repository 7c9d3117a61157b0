"""Observability indices and optimal pose choice, on synthetic per-pose Jacobians."""

import numpy as np
import pytest

from robocal.solver.observability import observability_indices, select_poses, unit_columns


def synthetic(n=120, rows=6, P=10, seed=0):
    """Per-pose Jacobians with badly scaled columns and one weakly excited direction."""
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(n, rows, P))
    J[..., 0] *= 1000.0  # a length next to angles
    J[..., -1] *= rng.uniform(0.0, 0.3, size=(n, 1))  # only some poses excite the last column
    return J


def log_det(J, idx):
    Js = unit_columns(J)[idx].reshape(-1, J.shape[-1])
    return np.linalg.slogdet(Js.T @ Js)[1]


def test_indices_of_a_known_matrix():
    J = np.diag([4.0, 2.0, 1.0])
    ind = observability_indices(J)
    assert ind["log_det"] == pytest.approx(2 * np.log(8.0))
    assert ind["condition"] == pytest.approx(4.0)
    assert ind["O1"] == pytest.approx(2.0 / np.sqrt(3))
    assert ind["O5"] == pytest.approx(1.0 / 4.0)
    # per-pose blocks are stacked
    assert observability_indices(J.reshape(3, 1, 3)) == ind


def test_rank_deficient_indices():
    ind = observability_indices(np.ones((2, 3)))
    assert ind["log_det"] == -np.inf and ind["condition"] == np.inf and ind["O5"] == 0.0


def test_unit_columns_have_unit_norm_over_all_poses():
    J = unit_columns(synthetic())
    np.testing.assert_allclose(np.sqrt(np.einsum("nrp,nrp->p", J, J)), 1.0)


def test_d_optimal_choice_is_a_local_optimum_and_beats_random():
    J = synthetic()
    k = 8
    idx = select_poses(J, k, "D")
    assert len(set(idx.tolist())) == k and np.all(np.diff(idx) > 0)
    best = log_det(J, idx)
    # no single exchange improves it (what the Fedorov exchange stops on)
    for pos in range(k):
        for j in np.setdiff1d(np.arange(len(J)), idx)[::7]:
            trial = idx.copy()
            trial[pos] = j
            assert log_det(J, trial) <= best + 1e-8
    rng = np.random.default_rng(1)
    randoms = [log_det(J, rng.choice(len(J), k, replace=False)) for _ in range(50)]
    assert best > max(randoms)


def test_choice_does_not_depend_on_parameter_units():
    J = synthetic()
    scaled = J * np.geomspace(1e-3, 1e3, J.shape[-1])
    np.testing.assert_array_equal(select_poses(J, 8), select_poses(scaled, 8))


def test_o5_choice_has_the_larger_o5():
    J = unit_columns(synthetic())
    d, o5 = select_poses(J, 8, "D"), select_poses(J, 8, "O5")
    assert observability_indices(J[o5])["O5"] >= observability_indices(J[d])["O5"]
    assert observability_indices(J[d])["log_det"] >= observability_indices(J[o5])["log_det"]


def test_select_rejects_bad_arguments():
    J = synthetic(n=5)
    with pytest.raises(ValueError, match="criterion"):
        select_poses(J, 2, "A")
    with pytest.raises(ValueError, match="6 of 5"):
        select_poses(J, 6)
    np.testing.assert_array_equal(select_poses(J, 5), np.arange(5))
