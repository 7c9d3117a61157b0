"""Normal equations assembled from flange twists equal J'J and J'r of the explicit Jacobian."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from robocal.solver.identifiability import structural
from robocal.solver.identify import SumOfSquares, register, start_fit
from robocal.solver.kinematics import Layout, predict, predict_rows
from robocal.solver.lm import levenberg_marquardt
from robocal.solver.normal import PointNormal
from robocal.solver.robot import IRB2600
from tests.robots import KUKA_LIKE, PUMA_LIKE

SMRS = [[60, 0, 35], [-30, 52, 35], [-30, -52, 35], [0, 0, 80]]


def _problem(robot, seed, m=40, K=3, missing=0.0):
    rng = np.random.default_rng(seed)
    base = np.array([[0, -1, 0, 2500.0], [1, 0, 0, 300.0], [0, 0, 1, -400.0], [0, 0, 0, 1]])
    lay = Layout(robot, base, tuple("ABCD"[:K]))
    x = lay.initial(SMRS[:K]) + rng.normal(0, 1e-3, lay.n_params)
    q = rng.uniform(robot.lower, robot.upper, size=(m, robot.n_joints))
    meas = predict(lay, x + rng.normal(0, 1e-3, lay.n_params), q) + rng.normal(0, 0.01, (m, K, 3))
    meas[rng.random((m, K)) < missing] = np.nan
    return lay, x, q, meas


def _explicit(lay, x, q, meas, cols):
    mask = np.all(np.isfinite(meas), axis=-1)
    p, Jt = predict_rows(lay, x, q, mask, cols)
    J = Jt.reshape(len(cols), -1)
    r = (p - meas[mask]).ravel()
    return r, J


@pytest.mark.parametrize(
    "robot,seed,K,missing",
    [
        (IRB2600, 0, 3, 0.0),
        (IRB2600, 1, 3, 0.3),
        (KUKA_LIKE, 2, 3, 0.2),
        (PUMA_LIKE, 3, 4, 0.25),
        (PUMA_LIKE, 4, 2, 0.0),
        (KUKA_LIKE, 5, 1, 0.1),
    ],
)
def test_normal_equations_equal_the_explicit_jacobian(robot, seed, K, missing):
    lay, x, q, meas = _problem(robot, seed, K=K, missing=missing)
    rng = np.random.default_rng(seed + 100)
    cols = rng.permutation(lay.n_params)[: rng.integers(lay.n_params // 2, lay.n_params + 1)]
    r, J = _explicit(lay, x, q, meas, cols)
    mask = np.all(np.isfinite(meas), axis=-1)
    ne = PointNormal(lay, q, mask, meas, cols)(x)
    A = J @ J.T
    np.testing.assert_allclose(ne.A, A, atol=1e-10 * np.abs(A).max())
    np.testing.assert_allclose(ne.g, J @ r, atol=1e-10 * np.abs(J @ r).max())
    assert ne.cost == pytest.approx(r @ r, rel=1e-10)
    other = rng.normal(size=r.shape)
    np.testing.assert_allclose(ne.jt(other), J @ other, atol=1e-10 * np.abs(J @ other).max())


def test_base_and_smrs_alone_reuse_the_arm_and_agree():
    lay, x, q, meas = _problem(IRB2600, 7, missing=0.1)
    mask = np.all(np.isfinite(meas), axis=-1)
    cols = np.r_[
        np.arange(lay.base_slice.start, lay.base_slice.stop),
        np.arange(lay.target_slice.start, lay.target_slice.stop),
    ]
    points = PointNormal(lay, q, mask, meas, cols)
    assert points.arm_held
    y = x.copy()
    for step in range(3):  # the arm's frames are kept while only base and SMRs move
        y[cols] += 1e-3 * (step + 1)
        r, J = _explicit(lay, y, q, meas, cols)
        ne = points(y)
        np.testing.assert_allclose(ne.A, J @ J.T, atol=1e-10 * np.abs(J @ J.T).max())
        np.testing.assert_allclose(points.residual(y), r, atol=1e-9)


def test_levenberg_marquardt_reaches_scipys_minimum():
    lay, x, q, meas = _problem(KUKA_LIKE, 11, m=60)
    prob, x0 = register(
        KUKA_LIKE, np.array(SMRS[:3], float), ("A", "B", "C"), q, meas, refine=False
    )
    free = np.zeros(prob.layout.n_params, dtype=bool)
    free[[0, 1, 2, 5, 9, 13]] = True
    free[prob.layout.base_slice] = True
    free[prob.layout.target_slice] = True
    fit = SumOfSquares(prob, x0, free)
    xs, res = fit.fit()
    assert res.message == "converged" and res.njev <= 4
    idx = np.flatnonzero(free)

    def residual(z):
        y = x0.copy()
        y[idx] = z
        return fit.points.residual(y)

    ref = least_squares(residual, x0[idx], method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert res.cost <= 2 * ref.cost * (1 + 1e-8)
    np.testing.assert_allclose(res.cost, 2 * ref.cost, rtol=1e-8)
    # the fit's last residuals are those of its answer
    np.testing.assert_allclose(res.r, fit.points.residual(xs), atol=1e-12)


def test_levenberg_marquardt_with_explicit_jacobian_still_works():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 3, 50)
    y = 2.0 * np.exp(-1.3 * t) + rng.normal(0, 1e-3, t.size)

    def fun(p):
        e = np.exp(-p[1] * t)
        return p[0] * e - y, np.vstack([e, -p[0] * t * e])

    res = levenberg_marquardt(fun, [1.0, 1.0])
    np.testing.assert_allclose(res.x, [2.0, 1.3], atol=5e-3)
    assert res.message == "converged"


def test_register_fits_the_base_in_the_same_pass_as_the_normal_equations():
    lay, x, q, meas = _problem(PUMA_LIKE, 21, m=30, missing=0.2)
    wrong = Layout(lay.robot, np.eye(4), lay.target_names)
    mask = np.all(np.isfinite(meas), axis=-1)
    cols = np.arange(wrong.n_params)
    points = PointNormal(wrong, q, mask, meas, cols)
    x = wrong.initial(lay.targets(x))  # the nominal model, as register() takes it
    before = points.layout
    points, ne = points.register(x)
    assert points.layout is not before and np.array_equal(before.base_ref, np.eye(4))
    # the closed-form base of register() (30 poses: all of them) ...
    prob, _ = register(lay.robot, lay.targets(x), lay.target_names, q, meas, refine=False)
    np.testing.assert_allclose(points.layout.base_ref, prob.layout.base_ref, atol=1e-9)
    # ... and the normal equations there, as the explicit Jacobian gives them
    r, J = _explicit(points.layout, x, q, meas, cols)
    np.testing.assert_allclose(ne.A, J @ J.T, atol=1e-10 * np.abs(J @ J.T).max())
    np.testing.assert_allclose(ne.g, J @ r, atol=1e-10 * np.abs(J @ r).max())
    assert ne.cost == pytest.approx(r @ r, rel=1e-10)


@pytest.mark.parametrize("seed,missing", [(31, 0.0), (32, 0.15)])
def test_a_first_step_on_spread_poses_reaches_the_minimum_of_all_the_data(seed, missing):
    lay, x, q, meas = _problem(KUKA_LIKE, seed, m=400, missing=missing)
    targets = lay.targets(x)
    prob, x0 = register(KUKA_LIKE, targets, lay.target_names, q, meas, refine=False)
    free = structural(prob.layout, x0, np.ones(prob.layout.n_params, dtype=bool)).free
    fit, first = start_fit(KUKA_LIKE, targets, lay.target_names, q, meas, free)
    assert fit.start == {"poses": 58, "stepped": True}  # every 7th pose
    xs, res = fit.fit(first)
    whole = SumOfSquares(prob, x0, free)
    ref_x, ref = whole.fit(whole.normal())  # normal equations of all the poses from the start
    assert whole.start == {}
    assert res.message == "converged" and res.njev <= 2
    assert res.cost == pytest.approx(ref.cost, rel=1e-8)  # the fits stop at ftol 1e-8
    # the same arm, base and SMRs, whatever base_ref each fit kept
    np.testing.assert_allclose(
        predict(fit.prob.layout, xs, q), predict(prob.layout, ref_x, q), atol=1e-6
    )
    # a fit on a registered problem takes the same first step by itself
    again = SumOfSquares(prob, x0, free)
    xa, ra = again.fit()
    assert again.start == {"poses": 58, "stepped": True} and ra.njev <= 2
    assert ra.cost == pytest.approx(ref.cost, rel=1e-8)
