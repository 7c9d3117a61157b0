"""The null's resamples streamed in blocks (issue 24): the same draws and figures as one whole
draw, and memory that does not grow with poses x resamples."""

import tracemalloc

import numpy as np

from robocal.solver import selection, shift_scan
from robocal.solver.selection import SignFlips, linear_scores, rmse_gain_interval


def problem(m, rows_per=9, seed=0):
    """A current model, three candidates, a residual and a rigid shift's columns on m poses."""
    rng = np.random.default_rng(seed)
    rows = m * rows_per
    A = rng.normal(size=(rows, 8))
    blocks = [rng.normal(size=(rows, k)) for k in (1, 2, 6)]
    r = rng.normal(size=rows)
    pose_of_row = np.repeat(np.arange(m), rows_per)
    folds = [np.sort(rng.permutation(m)[i::5]) for i in range(5)]
    scans = {2: (rng.normal(size=(rows, 6)), rng.permutation(m))}
    return A, r, blocks, pose_of_row, folds, scans


def test_sign_flips_are_one_whole_draw_block_by_block():
    m, resamples = 2 * selection.POSE_BLOCK + 37, 2 * selection.RESAMPLE_BLOCK + 13
    whole = np.random.default_rng(7).choice([-1.0, 1.0], size=(m, resamples))
    flips = SignFlips(m, resamples, np.random.default_rng(7))
    got = np.concatenate([s for _, s in flips.blocks()], axis=1)
    assert np.array_equal(got, whole)
    assert flips.bits.nbytes < whole.nbytes / 60


def test_split_scan_carries_its_sums_across_blocks(monkeypatch):
    """The split scan a few visits at a time equals it in one block (the suffix sums carried on
    in the same order), so blocks do not change which split wins."""
    args = problem(60)
    one = linear_scores(*args[:5], 60, resamples=40, scans=args[5])
    monkeypatch.setattr(selection, "SPLIT_BLOCK", 3)
    monkeypatch.setattr(selection, "RESAMPLE_BLOCK", 8)
    monkeypatch.setattr(selection, "POSE_BLOCK", 4)
    small = linear_scores(*args[:5], 60, resamples=40, scans=args[5])
    assert np.allclose(small.z, one.z, rtol=1e-12, atol=1e-12)
    assert np.allclose(small.null_max, one.null_max, rtol=1e-12, atol=1e-12)
    assert np.array_equal(small.pose_gain, one.pose_gain)


def test_null_memory_does_not_grow_with_poses_times_resamples():
    """4,000 poses and 2,000 resamples: a (poses, resamples) array of floats alone would take
    61 MiB, the split scan's (poses, 6, resamples) 366 MiB; the inputs take 3 MiB."""
    m = 4000
    args = problem(m)
    tracemalloc.start()
    try:
        linear_scores(*args[:5], m, resamples=2000, scans=args[5])
        peak = tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()
    assert peak < 40


def test_gain_interval_in_blocks_is_the_whole_bootstrap():
    rng = np.random.default_rng(3)
    m, resamples = 5000, 2000
    before, after = rng.uniform(0, 1, m), rng.uniform(0, 1, m)
    n = rng.integers(0, 4, m).astype(float)
    idx = np.random.default_rng(0).integers(0, m, size=(resamples, m))
    nn = n[idx].sum(axis=1)
    ok = nn > 0
    g = np.sqrt(before[idx].sum(axis=1)[ok] / nn[ok]) - np.sqrt(after[idx].sum(axis=1)[ok] / nn[ok])
    want = np.quantile(g, [(1 - 0.95) / 2, (1 + 0.95) / 2])
    assert rmse_gain_interval(before, after, n) == tuple(want)


def test_shift_gains_in_a_batch_are_the_gaps_one_by_one():
    rng = np.random.default_rng(5)
    k, p = 50, 7
    Z = rng.normal(size=(k, 30, 6))
    ZZ = np.einsum("nci,ncj->nij", Z, Z)
    QZ = rng.normal(size=(k, p, 6)) * 0.1
    Zr, Qr = rng.normal(size=(k, 6)), rng.normal(size=p)
    ZZ[3] = 0.0  # a singular gap: it gains nothing, the others are still solved
    QZ[3] = 0.0
    got = shift_scan.shift_gains(ZZ, QZ, Zr, Qr)
    for n in range(k):
        G = ZZ[n] - QZ[n].T @ QZ[n]
        G = G + 1e-12 * np.trace(G) * np.eye(6)
        b = Zr[n] - QZ[n].T @ Qr
        want = -np.inf if n == 3 else b @ np.linalg.solve(G, b)
        assert np.isclose(got[n], want, rtol=1e-10)
