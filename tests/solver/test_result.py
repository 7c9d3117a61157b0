"""One result type for every method, and QP subproblems that say whether they were solved."""

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.solver import minimax as minimax_module
from robocal.solver import qp
from robocal.solver.calibrate import METHODS, Calibration, calibrate
from robocal.solver.problem import Problem
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS

NAMES = ("A", "B", "C")
COMMON = ("method", "x", "cost", "success", "status", "message", "nit", "F", "condition")


@pytest.fixture(scope="module")
def data():
    cell = VirtualCell.random(IRB2600, TARGETS, seed=11)
    meas = cell.campaign(80, seed=12)
    return np.array([TARGETS[t] for t in NAMES]), meas.q, meas.xyz


def _fit(data, method, **kw):
    targets, q, xyz = data
    return calibrate(Problem(IRB2600, targets, NAMES, q, xyz), method, **kw)


@pytest.mark.parametrize("method", [*(m for m in METHODS if m != "ls-single"), "ls-single:B"])
def test_every_method_returns_the_same_result_type(data, method):
    cal = _fit(data, method)
    assert isinstance(cal, Calibration)
    assert cal.method == cal["method"] and set(dir(cal)) >= set(COMMON)  # scipy's result's manners
    with pytest.raises(AttributeError):
        cal.no_such_figure  # noqa: B018
    for key in COMMON:
        assert key in cal, key
    assert cal.success and cal.status == 0, cal.message
    assert cal.iterations == cal.nit
    rows = [1] if method == "ls-single:B" else [0, 1, 2]
    if method == "minimax":
        assert cal.cost == pytest.approx(cal.F.max()) and cal.worst_F == cal.cost
        assert cal.worst_target == NAMES[int(np.argmax(cal.F))]
        assert cal.qp_converged and cal.qp_iterations > 0 and cal.history[-1] <= cal.history[0]
    elif method != "ls-pose":
        assert cal.cost == pytest.approx(cal.F[rows].sum())
    if method != "nominal":
        assert cal.lm["iterations"] >= 1 and "structural_condition" in cal


def test_primal_dual_reports_a_subproblem_it_did_not_solve():
    rng = np.random.default_rng(3)
    n, K = 6, 4
    B = rng.normal(size=(n, n))
    H, g, F = B @ B.T + np.eye(n), rng.normal(size=(K, n)), rng.uniform(1, 2, K)
    A, c = np.zeros((0, n)), np.zeros(0)
    assert qp.primal_dual(H, g, F, F.max(), A, c).converged
    cut = qp.primal_dual(H, g, F, F.max(), A, c, max_iter=2)
    assert not cut.converged and cut.message == "iteration limit reached"
    assert qp.exact(H, g, F, F.max(), A, c).converged


def test_minimax_notes_unsolved_subproblems(data, monkeypatch):
    def short(*args):
        return qp.primal_dual(*args, max_iter=3)

    monkeypatch.setitem(minimax_module.SOLVERS, "primal-dual", short)
    cal = _fit(data, "minimax")
    assert not cal.qp_converged
    assert "QP subproblem(s) not solved to tolerance" in cal.message
    assert not cal.success and cal.status != 0
