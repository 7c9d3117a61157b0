"""Planning's memory linear in the SMRs (issue 20: 300 SMRs took 6.9 GB), its choice and
figures the same as the dense Jacobians gave (the code before, kept here as the reference)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robocal.drivers.planning import candidate_jacobians, plan_poses
from robocal.server.bench.scale import peak_mb, plan_at, smr_ring
from robocal.solver import identifiability as ident
from robocal.solver import observability as obs
from robocal.solver.kinematics import Layout, predict_rows
from robocal.solver.robot import IRB2600

from .test_planning import cell


def dense_jacobians(base, targets, q) -> np.ndarray:
    """The pre-issue-20 candidate_jacobians: (m, 3K, P) with every zero."""
    names = tuple(f"T{i + 1}" for i in range(len(targets)))
    lay = Layout(IRB2600, base, names)
    x = lay.initial(targets)
    cols = np.flatnonzero(ident.structural(lay, x, np.ones(lay.n_params, dtype=bool)).free)
    _, Jt = predict_rows(lay, x, q, np.ones((len(q), len(names)), dtype=bool), cols)
    return Jt.reshape(len(cols), len(q), 3 * len(names)).transpose(1, 2, 0)


def dense_select(J, k, criterion):
    """The pre-issue-20 select_poses: every candidate's (P, P) information at once."""
    J = obs.unit_columns(J)
    A = obs.information(J)
    N, P = A.shape[:2]
    M = obs.RIDGE * np.trace(A.sum(axis=0)) / (N * P) * np.eye(P)

    def scores(criterion, M):
        if criterion == "O5":
            return obs._o5(M + A)
        G = J @ np.linalg.inv(M)
        S = np.eye(J.shape[1]) + G @ J.transpose(0, 2, 1)
        return obs._log_det(M[None])[0] + obs._log_det(S)

    free, chosen = np.ones(N, dtype=bool), []
    for _ in range(k):
        j = int(np.argmax(np.where(free, scores("D", M), -np.inf)))
        chosen.append(j)
        free[j] = False
        M = M + A[j]
    best = float(obs.CRITERIA[criterion](M[None])[0])
    for _ in range(obs.MAX_SWEEPS):
        improved = False
        for pos in range(k):
            rest = M - A[chosen[pos]]
            score = np.where(free, scores(criterion, rest), -np.inf)
            j = int(np.argmax(score))
            if score[j] > best + obs.EXCHANGE_TOL * max(1.0, abs(best)):
                free[chosen[pos]], free[j] = True, False
                chosen[pos], M, best = j, rest + A[j], float(score[j])
                improved = True
        if not improved:
            break
    return np.sort(np.array(chosen))


@pytest.mark.parametrize(("smrs", "criterion"), [(1, "D"), (3, "D"), (5, "D"), (3, "O5")])
def test_the_choice_and_its_figures_are_the_dense_jacobians(smrs, criterion):
    base, targets = cell().base, smr_ring(smrs)
    q = plan_poses(IRB2600, base, targets, 120, np.random.default_rng(smrs))
    J = candidate_jacobians(IRB2600, base, targets, q)
    dense = dense_jacobians(base, targets, q)
    np.testing.assert_array_equal(J.dense(), dense)
    chosen = obs.select_poses(J, 12, criterion)
    np.testing.assert_array_equal(chosen, dense_select(dense, 12, criterion))
    for idx in (chosen, np.arange(12)):
        new = obs.observability_indices(obs.unit_columns(J)[idx])
        old = obs.observability_indices(obs.unit_columns(dense)[idx])
        assert new == pytest.approx(old, rel=1e-9)


def test_planning_memory_at_16_smrs_is_linear_in_the_smrs():
    # Memory is deterministic (the same arrays every run), so this bound cannot flake: memory
    # a + b x SMRs with a >= 0 gives at most 16/3 the 3-SMR figure; the dense Jacobians before
    # issue 20 grew with the square (9x from 3 to 16 SMRs here, 6.9 GB at 300).
    three, sixteen = peak_mb(plan_at(3)), peak_mb(plan_at(16))
    print(json.dumps({"plan_peak_mb": {"3_smrs": round(three, 2), "16_smrs": round(sixteen, 2)}}))
    assert sixteen < 16 / 3 * three
