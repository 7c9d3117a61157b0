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

import itertools
from dataclasses import dataclass

import numpy as np

from .finite import finite

ALPHA = 0.003  # nominal family-wise false-alarm rate per round of selection
RESAMPLES = 2000  # sign-flip resamples of the null (0.997 quantile from its 6 largest)
RANK_TOL = 1e-9
POSE_BLOCK = 512  # poses per block of row-wise work
RESAMPLE_BLOCK = 64  # resamples per block (a multiple of 8: the signs are held as bits)


def _pinv_sym(G: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of a symmetric positive semi-definite Gram matrix, rank-truncated."""
    if G.shape[0] == 0:
        return G
    w, V = np.linalg.eigh(finite(G, "the information matrix"))
    keep = w > RANK_TOL * max(w[-1], 1e-300)
    return (V[:, keep] / w[keep]) @ V[:, keep].T


def _pinv_stack(G: np.ndarray) -> np.ndarray:
    """_pinv_sym of each matrix of a stack (n, k, k)."""
    w, V = np.linalg.eigh(finite(G, "the information matrix"))
    keep = w > RANK_TOL * np.maximum(w[:, -1:], 1e-300)
    inv = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    return (V * inv[:, None, :]) @ np.swapaxes(V, 1, 2)


def _pose_sums(rows_of, starts: np.ndarray, poses: np.ndarray, m: int, n_rows: int) -> np.ndarray:
    """Per pose, the sum over its rows of rows_of(row slice), built POSE_BLOCK poses at a time.

    Rows are grouped by pose; a row-wise product (a Jacobian times a residual, an outer product of
    columns) is then never made for all rows at once."""
    out = None
    for i in range(0, len(starts), POSE_BLOCK):
        j = min(i + POSE_BLOCK, len(starts))
        lo, hi = starts[i], starts[j] if j < len(starts) else n_rows
        part = np.add.reduceat(rows_of(slice(lo, hi)), starts[i:j] - lo, axis=0)
        if out is None:
            out = np.zeros((m, *part.shape[1:]))
        out[poses[i:j]] = part
    return np.zeros((m,)) if out is None else out


class SignFlips:
    """The null's random signs, one per pose and resample, held as bits (an (m, resamples) array
    of floats would grow with poses x resamples).

    Drawn POSE_BLOCK poses at a time from the one stream, pose by pose as one (m, resamples)
    draw takes them (the bit generator keeps a drawn word's unused half from one call to the
    next), so the resamples are those of one draw whatever the block size."""

    def __init__(self, m: int, resamples: int, rng: np.random.Generator):
        self.m, self.n = m, resamples
        self.bits = np.zeros((m, (resamples + 7) // 8), np.uint8)
        for i in range(0, m if resamples else 0, POSE_BLOCK):
            k = min(POSE_BLOCK, m - i)
            self.bits[i : i + k] = np.packbits(rng.integers(0, 2, size=(k, resamples)) > 0, axis=1)

    def blocks(self, poses: np.ndarray | None = None):
        """(columns, signs (poses, columns) of +-1) over all resamples, RESAMPLE_BLOCK at a time;
        poses default all."""
        held = self.bits if poses is None else self.bits[poses]
        for c0 in range(0, self.n, RESAMPLE_BLOCK):
            c1 = min(c0 + RESAMPLE_BLOCK, self.n)
            bits = np.unpackbits(held[:, c0 // 8 : (c1 + 7) // 8], axis=1)[:, : c1 - c0]
            yield slice(c0, c1), bits * 2.0 - 1.0


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
    prior: tuple[np.ndarray, np.ndarray] | None = None,
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
    thousands of null resamples cost a product of (columns x poses) by (poses x resamples),
    taken RESAMPLE_BLOCK resamples at a time: memory grows with the poses alone, not with poses
    x resamples (SignFlips holds the signs as bits).

    prior: (D, rp), the geometry prior's rows (solver.prior) on A's first columns, D (k, <= P)
    and their residual rp (k,) at the fit: rows every fold trains on and none tests, which the
    null leaves at zero (the current model, taken as the truth, is where the prior is centred).
    """
    rng = np.random.default_rng(seed)
    sizes = [A.shape[1]] + [B.shape[1] for B in blocks]
    J = np.concatenate([A] + list(blocks), axis=1)
    # spans unchanged; fair rank tests (the norms taken per block: the same sums, without a
    # squared copy of the whole Jacobian)
    norms = np.concatenate([np.linalg.norm(X, axis=0) for X in [A] + list(blocks)])
    J /= np.maximum(norms, 1e-300)
    cuts = np.cumsum([0] + sizes)
    a = slice(0, sizes[0])
    rows = A.shape[0]
    starts = np.flatnonzero(np.r_[True, np.diff(pose_of_row) != 0])
    poses = pose_of_row[starts]
    r0 = r if null_residual is None else null_residual

    def per_pose(v):  # per pose X_p' v_p and v_p' v_p
        G = _pose_sums(lambda s: J[s] * v[s, None], starts, poses, m, rows)
        vv = np.zeros(m)
        vv[poses] = np.add.reduceat(v * v, starts)
        return G, vv

    (Gp, rr), (G0, rr0) = per_pose(r), per_pose(r0)
    # the statistics are ratios of sums of squares: a residual's overall scale does not matter
    flips = SignFlips(m, resamples, rng)

    def squares(idx):
        return np.r_[rr[idx].sum(), np.full(resamples, rr0[idx].sum())]

    # X' R over all poses and over each fold's test poses: the observed residual, then every
    # resample, the resamples' signs taken a block at a time
    X_all = np.empty((J.shape[1], 1 + resamples))
    X_fold = [np.empty_like(X_all) for _ in folds]
    X_all[:, 0] = Gp.sum(axis=0)
    for X, test_poses in zip(X_fold, folds):
        X[:, 0] = Gp[test_poses].sum(axis=0)
    for cols, S in flips.blocks():
        cols = slice(1 + cols.start, 1 + cols.stop)
        X_all[:, cols] = G0.T @ S
        for X, test_poses in zip(X_fold, folds):
            X[:, cols] = G0[test_poses].T @ S[test_poses]
    JJ_all = J.T @ J
    rr_prior = 0.0
    if prior is not None:
        D = np.zeros((len(prior[1]), sizes[0]))
        D[:, : prior[0].shape[1]] = prior[0]
        D /= np.maximum(norms[a], 1e-300)  # as J's columns
        JJ_all[a, a] += D.T @ D
        X_all[a, 0] += D.T @ prior[1]
        rr_prior = float(prior[1] @ prior[1])
    C = len(blocks)
    gain = np.zeros((C, 1 + resamples))
    fresh = np.zeros(rows)  # held-out residual of the model the training poses alone would pick
    pose_gain = np.zeros((C, m))
    pose_sse = np.zeros(m)
    sse = np.zeros(1 + resamples)
    for X_S, test_poses in zip(X_fold, folds):
        test_rows = np.isin(pose_of_row, test_poses)
        Js = J[test_rows]
        JJ_S = Js.T @ Js
        JJ_T = JJ_all - JJ_S
        X_T = X_all - X_S
        AA_inv = _pinv_sym(JJ_T[a, a])
        coefA = AA_inv @ X_T[a]  # the current model refitted on the training poses
        e0_obs = r[test_rows] - Js[:, a] @ coefA[:, 0]
        fresh[test_rows] = e0_obs
        s2 = (rr.sum() + rr_prior - rr[test_poses].sum() - coefA[:, 0] @ X_T[a, 0]) / max(
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
            squares(np.arange(m)) + np.r_[rr_prior, np.zeros(resamples)],
            flips,
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
SPLIT_BLOCK = 512  # visits per block of the split scan (a block's arrays stay in cache)


def _split_scan(A, Z, r, r0, starts, poses, order, XA, AA, rr_total, flips: SignFlips):
    """Per residual column, the best in-sample log error ratio of a rigid shift after any split.

    For the split before the n-th pose visited, the shift's columns are Z on the later poses; their
    Gram sums are suffix sums in visit order, so all splits cost one pass. That pass goes through
    the resamples RESAMPLE_BLOCK at a time and through the splits SPLIT_BLOCK at a time from the
    last, each block's suffix sums carried on from the one after it: the per-pose products of the
    shift's columns with the signed residuals are never held for all poses and resamples at once.
    """
    m, rows = flips.m, len(r)
    Z = Z / np.maximum(np.linalg.norm(Z, axis=0), 1e-300)
    Zr = _pose_sums(lambda s: Z[s] * r[s, None], starts, poses, m, rows)
    Z0 = _pose_sums(lambda s: Z[s] * r0[s, None], starts, poses, m, rows)
    ZA = _pose_sums(lambda s: Z[s][:, :, None] * A[s][:, None, :], starts, poses, m, rows)
    ZZ = _pose_sums(lambda s: Z[s][:, :, None] * Z[s][:, None, :], starts, poses, m, rows)
    AA_inv = _pinv_sym(AA)
    H = AA_inv @ XA
    rss0 = rr_total - np.sum(XA * H, axis=0)
    best = np.zeros(flips.n + 1)
    first, end = EDGE_POSES, m - EDGE_POSES + 1  # the splits n: first <= n < end
    if end > first:
        suffix = lambda v: np.cumsum(v[::-1], axis=0)[::-1][first:end]  # noqa: E731
        sZA = suffix(ZA[order])
        G_inv = _pinv_stack(suffix(ZZ[order]) - sZA @ AA_inv @ np.swapaxes(sZA, 1, 2))
        sZA = sZA.reshape(-1, sZA.shape[2])  # (splits x 6, P): one product per block
        Zr, Z0 = Zr[order], Z0[order]

        # suffix sums in place from the last visit back, each block of splits carrying them on
        # from the block after it: the additions of one pass over all visits, in the same order;
        # the splits outermost, so a block's columns stay in cache for all the resamples
        carry = np.zeros((Z.shape[1], 1 + flips.n))
        for hi in range(m, first, -SPLIT_BLOCK):
            lo = max(hi - SPLIT_BLOCK, first)
            at = slice(lo - first, max(min(hi, end), lo) - first)  # splits lo, lo + 1, ...
            ZA_at, G_at = sZA[6 * at.start : 6 * at.stop], G_inv[at]
            observed = [(slice(0, 1), Zr[lo:hi, :, None].copy())]
            signed = (
                (slice(1 + c.start, 1 + c.stop), Z0[lo:hi, :, None] * S[:, None, :])
                for c, S in flips.blocks(order[lo:hi])
            )
            for cols, sums in itertools.chain(observed, signed):
                if hi < m:
                    sums[-1] += carry[:, cols]
                for i in range(len(sums) - 2, -1, -1):  # a row at a time: np.cumsum down the
                    sums[i] += sums[i + 1]  # first axis strides through memory, 3x slower
                carry[:, cols] = sums[0]
                sums = sums[: at.stop - at.start]
                if not len(sums):  # the last visits, after the last split
                    continue
                b = sums - (ZA_at @ H[:, cols]).reshape(sums.shape)
                q = np.sum(b * (G_at @ b), axis=1).max(axis=0)
                best[cols] = np.maximum(best[cols], q)
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
    """Bootstrap interval over poses of the held-out RMS gain (before minus after), mm.

    The resamples are drawn a block at a time (about a million pose indices), from the one stream
    as one (resamples, m) draw would take them."""
    rng = np.random.default_rng(seed)
    m = len(n)
    block = max(1, 2**20 // max(m, 1))
    g = []
    for start in range(0, resamples, block):
        idx = rng.integers(0, m, size=(min(block, resamples - start), m))
        nn = n[idx].sum(axis=1)
        ok = nn > 0
        g.append(
            np.sqrt(sq_before[idx].sum(axis=1)[ok] / nn[ok])
            - np.sqrt(sq_after[idx].sum(axis=1)[ok] / nn[ok])
        )
    lo, hi = np.quantile(np.concatenate(g), [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def tied_suspect(
    trial, best: int, sc: Scores, joint: int | None, t_max: float, min_gain: float
) -> int:
    """The one-stiffness compliance of the gravity-loaded joint when it removes min_gain of the
    held-out error and the data cannot tell it from the best candidate (paired t over poses of
    the best's advantage below t_max), even below the family-wise bar; else the best.

    On 30-40 one-SMR poses of a real UR5, joint 2's compliance helped the other 960 poses in 45
    of 48 subsets, yet a neutral look-alike (a joint scale, joint 3's compliance) won the noisy
    cross-validation by chance in 4 and made them 2-8% worse: a tie goes to the physics.
    A periodic term is not displaced: over part of a joint's range a harmonic and the gravity
    torque look alike, and on simulated small campaigns a true one was renamed a compliance.
    """
    if joint is None or trial[best].name == "joint_periodic":
        return best
    for i, c in enumerate(trial):
        if not sc.gain[i] > min_gain * sc.sse:
            continue
        one_stiffness = c.masses is not None and c.keep is None
        if i != best and c.name == "joint_compliance" and one_stiffness and c.joint == joint:
            own, other = sc.pose_sse - sc.pose_gain[i], sc.pose_sse - sc.pose_gain[best]
            return i if paired_t(own, other) < t_max else best
    return best
