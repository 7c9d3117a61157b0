"""The adaptive campaign's numerics on a linear model, where every figure has an exact answer."""

import numpy as np
import pytest

from robocal.solver import adaptive


def _linear(rng, n, rows=6, P=8):
    """Per-pose rows of a linear model whose columns differ in scale (mm and rad alike)."""
    scale = np.geomspace(0.1, 10.0, P)
    return rng.normal(size=(n, rows, P)) * scale


def _tr_wc(J, W):
    return float(np.trace(W @ np.linalg.inv(np.einsum("nrp,nrq->pq", J, J))))


def test_each_pick_is_the_candidate_that_most_reduces_the_mean_prediction_variance():
    rng = np.random.default_rng(0)
    J0, cand = _linear(rng, 5), _linear(rng, 60)
    vol = _linear(rng, 300)
    W = adaptive.volume_weight(vol, 300 * 2)
    chosen = adaptive.choose_next(J0, cand, W, 3)
    J = J0
    for j in chosen:
        brute = [_tr_wc(np.concatenate([J, cand[i : i + 1]]), W) for i in range(len(cand))]
        for i in range(len(cand)):  # taken ones are out of the running
            if i in chosen[: list(chosen).index(j)]:
                brute[i] = np.inf
        assert j == int(np.argmin(brute))
        J = np.concatenate([J, cand[j : j + 1]])
    with pytest.raises(ValueError, match="cannot choose"):
        adaptive.choose_next(J0, cand[:2], W, 1, taken=[0, 1])


def test_i_optimal_choice_predicts_the_volume_better_than_random_poses():
    rng = np.random.default_rng(1)
    wins = 0
    for _ in range(10):
        J0, cand, vol = _linear(rng, 3), _linear(rng, 200), _linear(rng, 400)
        W = adaptive.volume_weight(vol, 400 * 2)
        chosen = adaptive.choose_next(J0, cand, W, 6)
        random_ = rng.choice(len(cand), 6, replace=False)
        a = _tr_wc(np.concatenate([J0, cand[chosen]]), W)
        b = _tr_wc(np.concatenate([J0, cand[random_]]), W)
        wins += a < b
    assert wins == 10


def _monte_carlo(rng, J, vol, noise_mm, runs=400):
    """Held-out RMS over the volume and leave-one-pose-out RMS of least-squares fits on J."""
    m, r, P = J.shape
    A = J.reshape(-1, P)
    s = noise_mm / np.sqrt(3.0)
    held, loo = [], []
    Ai = np.linalg.inv(A.T @ A)
    for _ in range(runs):
        x = rng.normal(size=P)
        y = A @ x + s * rng.normal(size=len(A))
        xh = Ai @ A.T @ y
        yv = vol @ x + s * rng.normal(size=vol.shape[:2])
        held.append(np.mean((vol @ xh - yv) ** 2) * 3.0)
        e = (y - A @ xh).reshape(m, r)
        for p in range(m):
            H = J[p] @ Ai @ J[p].T
            loo.append(np.sum(np.linalg.solve(np.eye(r) - H, e[p]) ** 2) / (r / 3.0))
    return float(np.sqrt(np.mean(held))), float(np.sqrt(np.mean(loo)))


def test_prediction_and_its_holdout_check_match_monte_carlo_on_a_linear_model():
    rng = np.random.default_rng(2)
    J, vol = _linear(rng, 12), _linear(rng, 300)
    noise = 0.02
    W = adaptive.volume_weight(vol, 300 * 2)
    held, loo = _monte_carlo(rng, J, vol, noise)
    pred = adaptive.predict(J, 12 * 2, W, noise, loo)
    assert pred.rms_mm == pytest.approx(held, rel=0.05)
    assert pred.expected_holdout_mm == pytest.approx(loo, rel=0.05)
    assert pred.kappa < 1.05
    # held-out residuals twice what the noise explains: the excess is put on the parameters'
    # part (the noise's part is the spec's), so the floor stays the noise
    twice = adaptive.predict(J, 12 * 2, W, noise, 2.0 * pred.expected_holdout_mm)
    noise_part = noise**2
    params_part = pred.expected_holdout_mm**2 - noise_part
    k2 = (4.0 * pred.expected_holdout_mm**2 - noise_part) / params_part
    assert twice.kappa == pytest.approx(np.sqrt(k2))
    assert twice.floor_mm == pytest.approx(noise)
    params = (pred.rms_mm**2 - noise**2) / pred.kappa**2  # the parameters' part, unscaled
    assert twice.rms_mm**2 == pytest.approx(noise**2 + k2 * params)


def test_prediction_matches_monte_carlo_with_errors_a_pose_shares():
    # an offset shared by a pose's readings (the arm's scatter) beside the tracker's noise: the
    # residuals show it, the held-out check sees the parameters less certain, and the
    # prediction, from the spec's noise, the fit's RMS and the held-out RMS, matches the truth
    rng = np.random.default_rng(5)
    J, vol = _linear(rng, 12), _linear(rng, 300)
    m, r, P = J.shape
    A = J.reshape(-1, P)
    noise, shared = 0.02, 0.02
    s = noise / np.sqrt(3.0)
    W = adaptive.volume_weight(vol, 300 * 2)
    Ai = np.linalg.inv(A.T @ A)
    held, preds = [], []
    for _ in range(300):
        x = rng.normal(size=P)
        y = A @ x + s * rng.normal(size=len(A)) + _shared(rng, m, r, shared)
        xh = Ai @ A.T @ y
        yv = (
            vol @ x
            + s * rng.normal(size=vol.shape[:2])
            + _shared(rng, 300, r, shared).reshape(300, r)
        )
        held.append(np.mean((vol @ xh - yv) ** 2) * 3.0)
        e = (y - A @ xh).reshape(m, r)
        H = np.einsum("nrp,pq,nsq->nrs", J, Ai, J)
        loo = np.linalg.solve(np.eye(r) - H, e[..., None])[..., 0]
        readings = m * r // 3
        fit = np.sqrt(np.sum(e**2) / readings)
        preds.append(
            adaptive.predict(J, readings, W, noise, np.sqrt(np.sum(loo**2) / readings), fit)
        )
        assert adaptive.holdout_rms(J, Ai, e, readings) == pytest.approx(preds[-1].holdout_mm)
    assert np.mean([p.rms_mm for p in preds]) == pytest.approx(np.sqrt(np.mean(held)), rel=0.03)
    assert np.mean([p.floor_mm for p in preds]) > 1.2 * noise  # the residuals showed the offsets


def _shared(rng, m, r, rms_mm):
    """An offset (3-D RMS rms_mm) per pose, the same on each of its r / 3 readings, as rows."""
    return np.tile(rng.normal(size=(m, 1, 3)) * rms_mm / np.sqrt(3.0), (1, r // 3, 1)).ravel()


def test_residuals_larger_than_the_noise_raise_the_reading_error():
    rng = np.random.default_rng(3)
    J, vol = _linear(rng, 12), _linear(rng, 50)
    W = adaptive.volume_weight(vol, 100)
    pred = adaptive.predict(J, 24, W, 0.02, 0.0, fit_rms_mm=0.05)
    dof = 72 - 8
    assert pred.error_mm == pytest.approx(0.05 * np.sqrt(72 / dof))
    assert adaptive.predict(J, 24, W, 0.02, 0.0, fit_rms_mm=0.001).error_mm == 0.02


def _prediction(**kw):
    base = dict(
        rms_mm=0.03,
        floor_mm=0.02,
        parameters_mm=0.0224,
        noise_mm=0.02,
        error_mm=0.02,
        holdout_mm=0.03,
        expected_holdout_mm=0.03,
        kappa=1.0,
        poses=50,
        equations=450,
        parameters=33,
    )
    return adaptive.Prediction(**{**base, **kw})


def test_the_rule_stops_on_the_upper_bound_the_floor_or_the_maximum():
    p = _prediction()
    assert p.upper_mm == pytest.approx(0.03 * (1 + adaptive.Z / 10.0))
    assert adaptive.decide(p, 0.034, 50, 80).reason == "target"
    assert not adaptive.decide(p, 0.032, 50, 80).stop  # within the target, not its bound
    assert adaptive.decide(p, 0.032, 80, 80).reason == "maximum"
    # too few equations or poses per parameter: no verdict but the maximum
    few = _prediction(poses=10, equations=90)
    assert not adaptive.decide(few, 1.0, 10, 80).stop
    # the floor above the target and the parameters' share small: more poses gain little
    flat = _prediction(rms_mm=0.0205, parameters_mm=0.0045, floor_mm=0.02)
    d = adaptive.decide(flat, 0.015, 50, 80)
    assert d.reason == "floor" and "floor" in d.message
    assert not adaptive.decide(_prediction(floor_mm=0.02), 0.015, 50, 80).stop
    with pytest.raises(ValueError, match="positive"):
        adaptive.decide(p, 0.0, 50, 80)


def test_the_holdout_spread_matches_monte_carlo_and_noise_alone_leaves_kappa_at_one():
    rng = np.random.default_rng(7)
    J = _linear(rng, 10)
    m, r, P = J.shape
    A = J.reshape(-1, P)
    C = np.linalg.inv(A.T @ A)
    readings = m * r // 3
    noise = 0.02
    s = noise / np.sqrt(3.0)
    W = adaptive.volume_weight(_linear(rng, 100), 200)
    ms, kappas = [], []
    for _ in range(2000):
        e = s * rng.normal(size=len(A))
        res = (e - A @ (C @ (A.T @ e))).reshape(m, r)
        loo = adaptive.holdout_rms(J, C, res, readings)
        ms.append(loo**2 / s**2)
        fit = np.sqrt(np.sum(res**2) / readings)
        kappas.append(adaptive.predict(J, readings, W, noise, loo, fit).kappa)
    assert np.std(ms) == pytest.approx(adaptive.holdout_spread(J, C, readings), rel=0.1)
    assert np.mean(ms) == pytest.approx(adaptive.expected_holdout(J, C, readings), rel=0.05)
    # noise alone: the check scales the parameters' part in about 1 % of the fits, not half
    assert np.mean(np.array(kappas) > 1.0) < 0.03
