"""Tests of solver.metrics against hand-computed cases and the paper's Table 3."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.solver import metrics as mt

NAMES = ("A", "B", "C")
# Right triangle whose spanned frame is the identity: x along A->B, z = +z.
TRI = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 60.0, 0.0]])


def rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(b):
    c, s = math.cos(b), math.sin(b)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(c_):
    c, s = math.cos(c_), math.sin(c_)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def iso_R(a, b, c):
    """R = Rz(c) Ry(b) Rx(a) from degrees, built by hand (independent of scipy's convention)."""
    a, b, c = np.radians([a, b, c])
    return rz(c) @ ry(b) @ rx(a)


def moved(points, R, t):
    """Points (..., 3) under the rigid motion p -> R p + t."""
    return points @ R.T + t


# --- sum_squares / rmse_phi / position_errors ---------------------------------------------


def test_sum_squares_hand():
    pred = np.zeros((2, 2, 3))
    meas = np.array([[[3.0, 4.0, 0.0], [1.0, 0.0, 0.0]], [[0.0, 0.0, 2.0], [1.0, 2.0, 2.0]]])
    np.testing.assert_allclose(mt.sum_squares(pred, meas), [25.0 + 4.0, 1.0 + 9.0])


def test_sum_squares_skips_missing():
    pred = np.zeros((3, 1, 3))
    meas = np.array([[[1.0, 0, 0]], [[np.nan, np.nan, np.nan]], [[0, 2.0, 0]]])
    # A missing reading contributes nothing (and does not turn F into NaN).
    np.testing.assert_allclose(mt.sum_squares(pred, meas), [5.0])
    # A single NaN coordinate already makes the whole reading missing.
    meas[1, 0] = [7.0, np.nan, 0.0]
    np.testing.assert_allclose(mt.sum_squares(pred, meas), [5.0])


def test_shape_mismatch_raises():
    with pytest.raises(ValueError):
        mt.sum_squares(np.zeros((2, 3, 3)), np.zeros((2, 2, 3)))
    with pytest.raises(ValueError):
        mt.position_errors(np.zeros((2, 3)), np.zeros((2, 3)))


# Paper Table 3: (F_1, F_2, F_3) in mm^2 and RMSE(phi) in mm, m = 100 poses.
TABLE3 = {
    0: ((325.90, 261.23, 373.88), 1.934),
    1: ((13.20, 14.72, 15.88), 0.399),
    2: ((15.68, 11.27, 14.41), 0.396),
    3: ((18.23, 14.38, 12.40), 0.427),
    4: ((14.02, 11.49, 13.24), 0.374),
    5: ((13.86, 12.49, 13.86), 0.372),
    6: ((15.94, 11.88, 14.00), 0.399),
}


@pytest.mark.parametrize("cond", sorted(TABLE3))
def test_rmse_phi_matches_table3(cond):
    F, expected = TABLE3[cond]
    F = np.array(F)
    # The paper rounds F to 0.01 and RMSE to 0.001 (condition 1: 15.88 -> 0.39850 vs 0.399),
    # so require the range reachable from the rounded F to meet the rounded RMSE interval.
    lo, hi = mt.rmse_phi(F - 0.005, 100), mt.rmse_phi(F + 0.005, 100)
    assert lo <= mt.rmse_phi(F, 100) <= hi
    assert hi >= expected - 5e-4 and lo <= expected + 5e-4
    assert mt.rmse_phi(F, 100) == pytest.approx(expected, abs=6e-4)


def test_rmse_phi_per_target_counts():
    # Equal counts reproduce the scalar form; unequal counts compare per-target mean squares.
    assert mt.rmse_phi([4.0, 9.0], [4, 4]) == pytest.approx(1.5)
    assert mt.rmse_phi([4.0, 9.0], [1, 9]) == pytest.approx(2.0)
    # A target with no readings is ignored; none at all gives NaN.
    assert mt.rmse_phi([4.0, 0.0], [1, 0]) == pytest.approx(2.0)
    assert math.isnan(mt.rmse_phi([0.0, 0.0], [0, 0]))


def test_position_errors_hand_and_nan():
    pred = np.array([[[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]])
    meas = np.array([[[1.0, 4.0, 5.0], [np.nan, 0.0, 0.0]]])
    ap = mt.position_errors(pred, meas)
    assert ap.shape == (1, 2)
    assert ap[0, 0] == pytest.approx(5.0)
    assert np.isnan(ap[0, 1])


# --- frames / Euler / orientation errors --------------------------------------------------


def test_frames_from_points_hand():
    pts = np.array([TRI, [[0, 0, 0], [0, 5, 0], [-1, 0, 0]]], dtype=float)
    R, o = mt.frames_from_points(pts)
    np.testing.assert_allclose(R[0], np.eye(3), atol=1e-15)
    np.testing.assert_allclose(o[0], [100 / 3, 20.0, 0.0])
    # x = +y, z = (0,5,0) x (-1,0,0) = (0,0,5) -> +z, y = z x x = -x.
    np.testing.assert_allclose(R[1], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(o[1], [-1 / 3, 5 / 3, 0.0])


def test_frames_use_first_three_targets_only():
    extra = np.concatenate([TRI, [[5.0, 5.0, 5.0], [np.nan, np.nan, np.nan]]])[None]
    R, o = mt.frames_from_points(extra)
    np.testing.assert_allclose(R[0], np.eye(3), atol=1e-15)
    assert np.all(np.isfinite(o))


def test_frames_missing_and_degenerate_rows_are_nan():
    pts = np.stack([TRI, TRI, TRI])
    pts[1, 2] = np.nan  # C missing
    pts[2] = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]  # collinear: no plane
    R, o = mt.frames_from_points(pts)
    assert np.all(np.isfinite(R[0])) and np.all(np.isfinite(o[0]))
    assert np.all(np.isnan(R[1:])) and np.all(np.isnan(o[1:]))


def test_frames_need_three_targets():
    with pytest.raises(ValueError):
        mt.frames_from_points(np.zeros((4, 2, 3)))


@pytest.mark.parametrize("abc", [(10.0, -20.0, 30.0), (-170.0, 45.0, 175.0), (0.0, 0.0, -90.0)])
def test_euler_xyz_is_iso_convention(abc):
    R = iso_R(*abc)[None]
    np.testing.assert_allclose(mt.euler_xyz(R)[0], abc, atol=1e-9)


def test_euler_xyz_nan_rows_and_gimbal_lock_silent():
    R = np.stack([np.full((3, 3), np.nan), iso_R(0, 90, 0)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        e = mt.euler_xyz(R)
    assert np.all(np.isnan(e[0]))
    assert e[1, 1] == pytest.approx(90.0)
    # At the singularity only a + c (sign-adjusted) is defined; the matrix must round-trip.
    np.testing.assert_allclose(iso_R(*e[1]), R[1], atol=1e-9)


@pytest.mark.parametrize("abc", [(3.0, -2.0, 5.0), (0.5, 0.25, -0.75), (20.0, 10.0, -40.0)])
def test_known_rotation_of_triangle(abc):
    Q = iso_R(*abc)
    pivot = np.array([250.0, -80.0, 900.0])
    pred = TRI[None]
    meas = moved(TRI - pivot, Q, pivot + np.array([1.0, 2.0, 3.0]))[None]
    angle = np.degrees(Rotation.from_matrix(Q).magnitude())
    assert mt.orientation_errors_log(pred, meas)[0] == pytest.approx(angle, abs=1e-9)
    # pred's frame is the identity (a = b = c = 0), so AO is |abc| of the applied rotation.
    np.testing.assert_allclose(mt.orientation_errors_euler(pred, meas)[0], np.abs(abc), atol=1e-9)
    # Swapping roles gives the same AO' (rotation angle of the inverse).
    assert mt.orientation_errors_log(meas, pred)[0] == pytest.approx(angle, abs=1e-9)


def test_ao_log_small_angle_precision():
    # 1 microradian should come out accurately, not be swamped by arccos round-off.
    eps = 1e-6
    meas = moved(TRI, rz(eps), 0.0)[None]
    assert mt.orientation_errors_log(TRI[None], meas)[0] == pytest.approx(np.degrees(eps), rel=1e-6)


def test_euler_difference_is_wrapped():
    pred = moved(TRI, iso_R(0, 0, 179.0), 0.0)[None]
    meas = moved(TRI, iso_R(0, 0, -179.0), 0.0)[None]
    np.testing.assert_allclose(mt.orientation_errors_euler(pred, meas)[0], [0, 0, 2.0], atol=1e-9)
    assert mt.orientation_errors_log(pred, meas)[0] == pytest.approx(2.0, abs=1e-9)


def test_ao_log_invariant_to_common_rigid_motion():
    rng = np.random.default_rng(0)
    m = 20
    pred = TRI[None] + rng.normal(0, 30, (m, 3, 3))
    meas = pred + rng.normal(0, 0.5, (m, 3, 3))
    Q = Rotation.from_rotvec([0.3, -1.1, 2.0]).as_matrix()
    t = np.array([1500.0, -200.0, 40.0])
    ao = mt.orientation_errors_log(pred, meas)
    ao_moved = mt.orientation_errors_log(moved(pred, Q, t), moved(meas, Q, t))
    assert np.all(ao > 0)
    np.testing.assert_allclose(ao_moved, ao, rtol=1e-7, atol=1e-10)
    # Position errors are invariant as well.
    np.testing.assert_allclose(
        mt.position_errors(moved(pred, Q, t), moved(meas, Q, t)),
        mt.position_errors(pred, meas),
        rtol=1e-9,
    )


def test_orientation_missing_reading_gives_nan_row():
    pred = np.stack([TRI, TRI])
    meas = np.stack([moved(TRI, rz(np.radians(1.0)), 0.0), TRI])
    meas[1, 1] = np.nan
    ao = mt.orientation_errors_log(pred, meas)
    assert ao[0] == pytest.approx(1.0)
    assert np.isnan(ao[1])
    assert np.all(np.isnan(mt.orientation_errors_euler(pred, meas)[1]))


# --- stats / improvement ------------------------------------------------------------------


def test_stats_hand_ignores_nan():
    s = mt.stats(np.array([[1.0, np.nan], [2.0, 3.0]]))
    assert s.n == 3
    assert s.mean == pytest.approx(2.0)
    assert s.std == pytest.approx(1.0)  # ddof = 1
    assert s.max == pytest.approx(3.0)
    assert s.rms == pytest.approx(math.sqrt(14 / 3))


def test_stats_degenerate():
    s = mt.stats([np.nan])
    assert s.n == 0 and all(math.isnan(v) for v in (s.mean, s.std, s.max, s.rms))
    s1 = mt.stats([2.0])
    assert s1.n == 1 and s1.mean == 2.0 and math.isnan(s1.std)


def test_improvement_pct():
    assert mt.improvement_pct(2.0, 0.5) == pytest.approx(75.0)
    assert mt.improvement_pct(1.0, 1.5) == pytest.approx(-50.0)
    assert math.isnan(mt.improvement_pct(0.0, 1.0))
    assert math.isnan(mt.improvement_pct(np.nan, 1.0))


# --- accuracy / compare / table3 ----------------------------------------------------------


def _offset_case(d):
    """Two poses of TRI, every target offset by d mm along x; one reading of B missing."""
    pred = np.stack([TRI, TRI + 10.0])
    meas = pred + np.array([d, 0.0, 0.0])
    meas[1, 1] = np.nan
    return pred, meas


def test_accuracy_hand():
    pred, meas = _offset_case(2.0)
    acc = mt.accuracy(pred, meas, NAMES)
    assert acc.n_poses == 2
    assert acc.n_readings == {"A": 2, "B": 1, "C": 2}
    assert acc.F == pytest.approx({"A": 8.0, "B": 4.0, "C": 8.0})
    assert acc.ap_per_target["B"].n == 1
    assert acc.ap.n == 5 and acc.ap.mean == pytest.approx(2.0)
    assert acc.ap.std == pytest.approx(0.0)
    # Missing readings are excluded from the RMS, not counted as zero error.
    assert acc.rmse == pytest.approx(2.0)
    assert acc.rmse_phi == pytest.approx(2.0)
    # A pure translation has no orientation error; pose 1 lacks B so has no orientation.
    assert acc.ao_log.n == 1 and acc.ao_log.max == pytest.approx(0.0, abs=1e-9)
    assert set(acc.ao_euler) == {"a", "b", "c"}
    assert acc.ao_euler["c"].n == 1


def test_accuracy_two_targets_has_no_orientation():
    pred, meas = _offset_case(1.0)
    acc = mt.accuracy(pred[:, :2], meas[:, :2], ("A", "B"))
    assert acc.ao_log is None and acc.ao_euler is None
    assert "ao_log" not in acc.to_json() and "ao_euler" not in acc.to_json()
    with pytest.raises(ValueError):
        mt.accuracy(pred, meas, ("A", "B"))


def test_accuracy_rotation_reported():
    pred = TRI[None]
    meas = moved(TRI, iso_R(0, 0, 2.0), 0.0)[None]
    acc = mt.accuracy(pred, meas, NAMES)
    assert acc.ao_log.mean == pytest.approx(2.0)
    assert acc.ao_euler["c"].mean == pytest.approx(2.0)
    assert acc.ao_euler["a"].mean == pytest.approx(0.0, abs=1e-9)


def test_compare_accuracy():
    pred = np.stack([TRI, TRI])
    before = mt.accuracy(pred, moved(pred, iso_R(0, 0, 2.0), [4.0, 0, 0]), NAMES)
    after = mt.accuracy(pred, moved(pred, iso_R(0, 0, 0.5), [1.0, 0, 0]), NAMES)
    cmp = mt.compare_accuracy(before, after)
    assert set(cmp.to_json()) == {"ap_mean", "ap_max", "ao_log_mean", "rmse"}
    assert cmp.ao_log_mean == pytest.approx(75.0)
    for v in (cmp.ap_mean, cmp.ap_max, cmp.rmse):
        assert 0.0 < v < 100.0
    same = mt.compare_accuracy(before, before)
    assert all(v == pytest.approx(0.0) for v in same.to_json().values())


def test_table3_columns_and_values():
    m = 100
    pred = np.zeros((m, 3, 3))
    # Per-target constant offsets chosen so that F = m * d^2 reproduces Table 3 condition 0.
    d = np.sqrt(np.array(TABLE3[0][0]) / m)
    meas0 = pred.copy()
    meas0[..., 2] = d
    meas5 = pred.copy()
    meas5[..., 2] = np.sqrt(np.array(TABLE3[5][0]) / m)
    t = mt.table3({"5": (pred, meas5), "0": (pred, meas0)}, NAMES)
    assert list(t) == ["5", "0"]
    assert t["0"]["F"] == pytest.approx(dict(zip(NAMES, TABLE3[0][0])))
    assert t["0"]["rmse_phi"] == pytest.approx(1.934, abs=5e-4)
    assert t["5"]["rmse_phi"] == pytest.approx(0.372, abs=5e-4)
    assert t["0"]["m"] == m and t["0"]["n_readings"] == {"A": m, "B": m, "C": m}


def test_table3_missing_readings_do_not_dilute_rmse_phi():
    pred = np.zeros((4, 3, 3))
    meas = pred + 1.0
    meas[0, 2] = np.nan
    t = mt.table3({"x": (pred, meas)}, NAMES)
    assert t["x"]["F"]["C"] == pytest.approx(9.0)
    assert t["x"]["rmse_phi"] == pytest.approx(math.sqrt(3.0))
