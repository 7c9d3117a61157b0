"""Which candidate extension pays off on unseen poses, with the false-alarm rate held per campaign.

Calibration is nearly linear at the scale of the errors it models (a millimetre on a metre-sized
arm), so around the current model's fit on all poses the cross-validation is a linear map of the
residuals: a fold refits the current model's columns A (and a candidate's columns C) to its
training readings and the held-out residual is what the refit leaves on the test readings. The
held-out gain of a candidate (the drop of the cross-validated sum of squares) is then a quadratic
form in the residuals, cheap for many residual vectors at once.

That makes a per-campaign null distribution affordable: a residual vector with a random sign per
pose (one sign for all readings of a pose, so an error shared by the SMRs of a pose stays shared)
is what the campaign would look like if the current model were the truth and its errors
symmetric. Each candidate's statistic, the log of the ratio of the cross-validated sums of
squares without and with it (free of the residuals' scale), is standardised by its own null mean
and spread (a compliance term with twelve columns and a scale error with one are then on the same
footing), and a candidate is accepted only when it exceeds the (1 - alpha) quantile of the MAXIMUM
over all candidates under the null, whatever the number of candidates.

Which residual to flip decides the power. The current model's own residual still holds the
effect: when the effect lives on a few poses (a scale error seen only at large |q|), its
sign-scrambled copy fits the candidate nearly as well as the real one, and a small campaign can
never reach significance. The residual left once the best candidate is fitted on all poses has
lost the noise that candidate was chosen for, and the null becomes too narrow. The resamples are
drawn from a fresh residual instead: in each fold, the candidate the training poses alone pick
(largest training gain beyond Akaike's two noise variances per column) is fitted on them, and the
held-out poses keep what it leaves; their noise took no part in the choice. Measured on clean
simulated campaigns it still runs slightly above its nominal rate (1.0% at alpha 0.5%, 0.5% at
0.3%), hence ALPHA.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .finite import finite

ALPHA = 0.003  # nominal family-wise false-alarm rate per round of selection
RESAMPLES = 2000  # sign-flip resamples of the null (0.997 quantile from its 6 largest)
RANK_TOL = 1e-9


def _pinv_sym(G: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of a symmetric positive semi-definite Gram matrix, rank-truncated."""
    if G.shape[0] == 0:
        return G
    w, V = np.linalg.eigh(finite(G, "the information matrix"))
    keep = w > RANK_TOL * max(w[-1], 1e-300)
    return (V[:, keep] / w[keep]) @ V[:, keep].T


@dataclass
class Scores:
    """Held-out gains of each candidate on the observed residuals and under the null."""

    sse: float  # cross-validated sum of squares of the current model
    pose_sse: np.ndarray  # (m,) its per-pose share
    gain: np.ndarray  # (C,) drop of the cross-validated sum of squares per candidate
    pose_gain: np.ndarray  # (C, m) per pose
    z: np.ndarray  # (C,) log error ratio standardised by the candidate's own null
    null_max: np.ndarray  # (B,) maximum over candidates of the standardised null statistic
    # (rows,) held-out residual of the model each fold's training poses pick: the null's source
    fresh: np.ndarray | None = None

    def threshold(self, alpha: float = ALPHA) -> float:
        return float(np.quantile(self.null_max, 1.0 - alpha))

    def p_value(self, c: int) -> float:
        """Share of null resamples whose best candidate beats candidate c's standardised gain."""
        return float((1 + np.sum(self.null_max >= self.z[c])) / (1 + len(self.null_max)))


def linear_scores(
    A: np.ndarray,
    r: np.ndarray,
    blocks: list[np.ndarray],
    pose_of_row: np.ndarray,
    folds: list[np.ndarray],
    m: int,
    resamples: int = RESAMPLES,
    seed: int = 0,
    scans: dict | None = None,
    null_residual: np.ndarray | None = None,
) -> Scores:
    """Cross-validated gains of candidate column blocks over the current model's columns A.

    A (rows, P) and r (rows,) are the current model's Jacobian and residual (prediction minus
    reading) on every measured coordinate, rows grouped by pose in pose order; blocks[c]
    (rows, p_c) a candidate's columns; pose_of_row (rows,) the pose of each row; folds the held-out
    poses of each fold. null_residual (rows,) is the residual whose per-pose sign flips make the
    null (default r; the module's docstring says why `Scores.fresh` is better). scans maps a
    candidate whose columns hang on a time found from the data (a base shift) to its rigid columns
    before the switch (rows, 6) and the poses' visit order: its significance is then judged by the
    best split over the whole campaign, in the data and in every null resample alike, so the
    search for the time does not pass for evidence.

    Every quantity of a fold's refit is a Gram matrix of the columns or a product X' R with the
    residual vectors R; with one sign per pose, X' R = sum over poses of (X_p' r_p) s_p, so the
    thousands of null resamples cost a product of (columns x poses) by (poses x resamples).
    """
    rng = np.random.default_rng(seed)
    sizes = [A.shape[1]] + [B.shape[1] for B in blocks]
    J = np.concatenate([A] + list(blocks), axis=1)
    J = J / np.maximum(np.linalg.norm(J, axis=0), 1e-300)  # spans unchanged; fair rank tests
    cuts = np.cumsum([0] + sizes)
    a = slice(0, sizes[0])
    rows = A.shape[0]
    starts = np.flatnonzero(np.r_[True, np.diff(pose_of_row) != 0])
    poses = pose_of_row[starts]
    r0 = r if null_residual is None else null_residual

    def per_pose(v):  # per pose X_p' v_p and v_p' v_p
        G = np.zeros((m, J.shape[1]))
        G[poses] = np.add.reduceat(J * v[:, None], starts, axis=0)
        vv = np.zeros(m)
        vv[poses] = np.add.reduceat(v * v, starts)
        return G, vv

    (Gp, rr), (G0, rr0) = per_pose(r), per_pose(r0)
    # the statistics are ratios of sums of squares: a residual's overall scale does not matter
    signs = rng.choice([-1.0, 1.0], size=(m, resamples))

    def products(idx):  # X' R over the poses idx: the observed residual, then every resample
        return np.concatenate([Gp[idx].sum(axis=0)[:, None], G0[idx].T @ signs[idx]], axis=1)

    def squares(idx):
        return np.r_[rr[idx].sum(), np.full(resamples, rr0[idx].sum())]

    X_all = products(np.arange(m))  # (P_all, 1+B)
    JJ_all = J.T @ J
    C = len(blocks)
    gain = np.zeros((C, 1 + resamples))
    fresh = np.zeros(rows)  # held-out residual of the model the training poses alone would pick
    pose_gain = np.zeros((C, m))
    pose_sse = np.zeros(m)
    sse = np.zeros(1 + resamples)
    for test_poses in folds:
        test_rows = np.isin(pose_of_row, test_poses)
        Js = J[test_rows]
        JJ_S = Js.T @ Js
        JJ_T = JJ_all - JJ_S
        X_S = products(test_poses)
        X_T = X_all - X_S
        AA_inv = _pinv_sym(JJ_T[a, a])
        coefA = AA_inv @ X_T[a]  # the current model refitted on the training poses
        e0_obs = r[test_rows] - Js[:, a] @ coefA[:, 0]
        fresh[test_rows] = e0_obs
        s2 = (rr.sum() - rr[test_poses].sum() - coefA[:, 0] @ X_T[a, 0]) / max(
            np.count_nonzero(~test_rows) - len(coefA), 1
        )  # training residual variance
        pick = 0.0
        sse_fold = (
            squares(test_poses)
            - 2.0 * np.sum(coefA * X_S[a], axis=0)
            + np.sum(coefA * (JJ_S[a, a] @ coefA), axis=0)
        )
        sse += sse_fold
        pose_sse += np.bincount(pose_of_row[test_rows], e0_obs**2, minlength=m)
        for c in range(C):
            b = slice(cuts[c + 1], cuts[c + 2])
            M = AA_inv @ JJ_T[a, b]  # the candidate's columns as the current model fits them
            BtBt = JJ_T[b, b] - JJ_T[a, b].T @ M
            if np.trace(BtBt) < 1e-9 * np.trace(JJ_T[b, b]):
                continue  # the current model absorbs the candidate entirely
            beta = _pinv_sym(BtBt) @ (X_T[b] - M.T @ X_T[a])
            DD = JJ_S[b, b] - JJ_S[a, b].T @ M - M.T @ JJ_S[a, b] + M.T @ JJ_S[a, a] @ M
            De0 = X_S[b] - JJ_S[a, b].T @ coefA - M.T @ X_S[a] + M.T @ JJ_S[a, a] @ coefA
            gain[c] += 2.0 * np.sum(beta * De0, axis=0) - np.sum(beta * (DD @ beta), axis=0)
            step = (Js[:, b] - Js[:, a] @ M) @ beta[:, 0]
            # training gain beyond what noise would give its columns (Akaike): chosen without
            # the held-out poses, so their noise is not what the choice removes
            merit = (X_T[b, 0] - M.T @ X_T[a, 0]) @ beta[:, 0] - 2.0 * (b.stop - b.start) * s2
            if merit > pick:
                pick, fresh[test_rows] = merit, e0_obs - step
            pose_gain[c] += np.bincount(
                pose_of_row[test_rows], 2.0 * e0_obs * step - step * step, minlength=m
            )
    # log of the cross-validated error ratio: free of the residuals' scale, so the null's residual
    # need only have the campaign's shape of error, not its size
    lr = np.log(sse / np.maximum(sse - gain, 1e-12 * sse))
    for c, (Z, order) in (scans or {}).items():
        lr[c] = _split_scan(
            J[:, a],
            Z,
            r,
            r0,
            starts,
            poses,
            order,
            X_all[a],
            JJ_all[a, a],
            squares(np.arange(m)),
            signs,
        )
    null = lr[:, 1:]
    if resamples == 0:
        return Scores(
            float(sse[0]), pose_sse, gain[:, 0], pose_gain, np.full(C, np.nan), np.zeros(0), fresh
        )
    mu = null.mean(axis=1, keepdims=True)
    sd = null.std(axis=1, keepdims=True)
    sd[sd <= 0] = np.inf
    z_all = (lr - mu) / sd
    return Scores(
        float(sse[0]),
        pose_sse,
        gain[:, 0],
        pose_gain,
        z_all[:, 0],
        z_all[:, 1:].max(axis=0) if C else np.zeros(resamples),
        fresh,
    )


EDGE_POSES = 5  # a split leaves at least this many poses on either side


def _split_scan(A, Z, r, r0, starts, poses, order, XA, AA, rr_total, signs):
    """Per residual column, the best in-sample log error ratio of a rigid shift after any split.

    For the split before the n-th pose visited, the shift's columns are Z on the later poses; their
    Gram sums are suffix sums in visit order, so all splits cost one pass.
    """
    m = signs.shape[0]
    Z = Z / np.maximum(np.linalg.norm(Z, axis=0), 1e-300)
    Zr = np.zeros((m, Z.shape[1]))
    Z0 = np.zeros((m, Z.shape[1]))
    ZA = np.zeros((m, Z.shape[1], A.shape[1]))
    ZZ = np.zeros((m, Z.shape[1], Z.shape[1]))
    Zr[poses] = np.add.reduceat(Z * r[:, None], starts, axis=0)
    Z0[poses] = np.add.reduceat(Z * r0[:, None], starts, axis=0)
    ZA[poses] = np.add.reduceat(Z[:, :, None] * A[:, None, :], starts, axis=0)
    ZZ[poses] = np.add.reduceat(Z[:, :, None] * Z[:, None, :], starts, axis=0)
    AA_inv = _pinv_sym(AA)
    H = AA_inv @ XA
    rss0 = rr_total - np.sum(XA * H, axis=0)
    per = np.concatenate(
        [Zr[order][:, :, None], Z0[order][:, :, None] * signs[order][:, None, :]], axis=2
    )
    sZr = np.cumsum(per[::-1], axis=0)[::-1]
    sZA = np.cumsum(ZA[order][::-1], axis=0)[::-1]
    sZZ = np.cumsum(ZZ[order][::-1], axis=0)[::-1]
    best = np.zeros(signs.shape[1] + 1)
    for n in range(EDGE_POSES, m - EDGE_POSES + 1):
        b = sZr[n] - sZA[n] @ H
        G = sZZ[n] - sZA[n] @ AA_inv @ sZA[n].T
        best = np.maximum(best, np.sum(b * (_pinv_sym(G) @ b), axis=0))
    return np.log(rss0 / np.maximum(rss0 - best, 1e-12 * rss0))


def paired_t(a: np.ndarray, b: np.ndarray) -> float:
    """t statistic over poses of the per-pose reduction a - b (positive when b is better)."""
    d = np.asarray(a) - np.asarray(b)
    sd = d.std(ddof=1)
    if sd == 0:
        return float("inf") if d.mean() > 0 else 0.0
    return float(d.mean() / (sd / np.sqrt(len(d))))


def rmse_gain_interval(
    sq_before: np.ndarray,
    sq_after: np.ndarray,
    n: np.ndarray,
    level: float = 0.95,
    resamples: int = 2000,
    seed: int = 0,
):
    """Bootstrap interval over poses of the held-out RMS gain (before minus after), mm."""
    rng = np.random.default_rng(seed)
    m = len(n)
    idx = rng.integers(0, m, size=(resamples, m))
    nn = n[idx].sum(axis=1)
    ok = nn > 0
    g = np.sqrt(sq_before[idx].sum(axis=1)[ok] / nn[ok]) - np.sqrt(
        sq_after[idx].sum(axis=1)[ok] / nn[ok]
    )
    lo, hi = np.quantile(g, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)
