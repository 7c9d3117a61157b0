"""Gross-outlier screening: readings that no plausible model fits (a mis-lock, a bumped SMR).

Three kinds of evidence, each judged against a robust scale taken from the campaign itself:

- SMR-to-SMR distances (poses with 2+ readings): no kinematic error changes them, so a distance
  off its campaign trend (temperature, time) by many times the tracker's own scatter is a bad
  reading, whatever the arm does.
- The within-pose residual (poses with 2+ readings): a reading's geometric residual minus the mean
  of its pose-mates'. An error shared by all SMRs of a pose (repeatability, settling, an effect
  the geometric model lacks) cancels; a single SMR displaced out of the SMRs' plane, which the
  distances cannot see, does not.
- The geometric residual itself, only for poses with a single reading, where nothing else tells.

At a pose whose readings disagree, the reading whose removal leaves the rest consistent is
excluded first (ties, as with two readings, go to the larger geometric residual). The geometric
fit (ls-sum) is then repeated without the excluded readings and every reading judged again,
until the set no longer changes.

Threshold: a reading is gross when its statistic exceeds the level a Gaussian would reach with
probability ALPHA over all the readings tested (Bonferroni over readings and kinds of evidence),
so a clean campaign of any size keeps about the same small chance of any false flag: a chi of 3
degrees of freedom for the within-pose residual (tracker noise is isotropic), a 1-D Gaussian
carrying all three axes' variance for the geometric residual (studentized by its leverage), as
the arm's own error at a pose may lie along one direction. The scale
is the larger of the median-based one and the one the 90% quantile implies, so heavy-tailed
unmodelled error (real arms) raises the scale instead of being called gross. The price: beyond
about 10% of gross readings the scale grows with them and fewer are found (never more).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from .finite import finite
from .identifiability import NotIdentifiable
from .problem import Problem

ALPHA = 0.01  # chance of any false flag on a clean campaign, by the Gaussian reference
MAX_ROUNDS = 6
TAIL_Q = 0.9  # quantile of |z| that, with the median, sets the robust scale
LEVERAGE_POSES = 2048  # poses whose Jacobian rows are formed at once for the leverage
RESOLUTION_MM = 1e-6  # below a nanometre a fit's own rounding, not a reading, sets the scatter


@dataclass(frozen=True)
class Outlier:
    """A reading excluded as a gross error: FORMATS.md section 5's `outliers` row."""

    pose: int | str  # the pose's id (an integer when it reads as one), or its number from 1
    target: str | int  # the SMR's name, or its index when no names were given
    residual_mm: float  # |geometric residual| under the fit without the excluded readings
    evidence: str  # which evidence judged it: distance, within-pose or geometric

    def to_json(self) -> dict:
        """The row as report.json and model.json have it."""
        return {
            "pose": self.pose,
            "target": self.target,
            "residual_mm": self.residual_mm,
            "evidence": self.evidence,
        }


@dataclass
class Screening:
    """Readings judged gross and the figures behind the judgement."""

    excluded: np.ndarray  # (m, K) bool
    residual_mm: (
        np.ndarray
    )  # (m, K) |geometric residual| under the fit without the excluded, NaN if missing
    evidence: dict = field(
        default_factory=dict
    )  # (pose, target) -> "distance" | "within-pose" | "geometric"
    scales_mm: dict = field(default_factory=dict)
    thresholds: dict = field(default_factory=dict)
    rounds: int = 0
    skipped: str | None = None  # why nothing could be judged (the data cannot fit the geometry)

    @property
    def count(self) -> int:
        return int(self.excluded.sum())

    def apply(self, meas: np.ndarray) -> np.ndarray:
        """The readings (m, K, 3) with the excluded ones set missing (NaN)."""
        out = np.array(meas, dtype=float)
        out[self.excluded] = np.nan
        return out

    def report(self, pose_ids=None, target_names=None) -> list[Outlier]:
        """The excluded readings as report rows: pose id (an integer when it reads as one), target
        name, residual (mm) and the evidence that judged it."""
        out = []
        for p, k, res, why in self.listing():
            pid = pose_ids[p] if pose_ids is not None else p + 1
            if isinstance(pid, str) and pid.lstrip("-").isdigit():
                pid = int(pid)
            out.append(
                Outlier(
                    pose=pid,
                    target=target_names[k] if target_names is not None else k,
                    residual_mm=round(res, 4),
                    evidence=why,
                )
            )
        return out

    def summary(self) -> dict:
        """Counts, scales and thresholds, for a model's fit statistics."""
        if self.skipped:
            return {"readings_excluded": 0, "skipped": self.skipped}
        return {
            "readings_excluded": self.count,
            "rounds": self.rounds,
            "scales_mm": {k: round(v, 5) for k, v in self.scales_mm.items() if np.isfinite(v)},
            "thresholds": {
                k: round(v, 3)
                for k, v in self.thresholds.items()
                if np.isfinite(self.scales_mm.get(k, np.nan))
            },
        }

    def listing(self) -> list[tuple[int, int, float, str]]:
        """(pose index, target index, residual mm, evidence) per excluded reading, largest first."""
        rows = [
            (int(p), int(k), float(self.residual_mm[p, k]), self.evidence.get((p, k), ""))
            for p, k in zip(*np.nonzero(self.excluded))
        ]
        return sorted(rows, key=lambda r: -r[2])


def robust_scale(z: np.ndarray, per_value_q50: float, per_value_q: float) -> float:
    """Scale of zero-centred values: the larger of what their median and their TAIL_Q quantile
    imply, given those quantiles (q50, q) of |z| for unit scale."""
    a = np.abs(z[np.isfinite(z)])
    if a.size == 0:
        return float("nan")
    return float(
        max(np.median(a) / per_value_q50, np.quantile(a, TAIL_Q) / per_value_q, RESOLUTION_MM)
    )


def _scale_1d(z):
    return robust_scale(z, stats.halfnorm.ppf(0.5), stats.halfnorm.ppf(TAIL_Q))


def distance_residuals(meas, keep, time_s=None, temp_c=None) -> dict:
    """Per target pair (i, j): the distance's departure (m,) from its campaign trend, fitted on
    the kept readings (constant, temperature and time, as thermal growth changes distances)."""
    K = meas.shape[1]
    out = {}
    for i in range(K):
        for j in range(i + 1, K):
            d = np.linalg.norm(meas[:, i] - meas[:, j], axis=-1)
            cols = [np.ones_like(d)]
            for a in (temp_c, time_s):
                if a is not None and np.isfinite(a).any():  # a column of blanks: not recorded
                    # where both readings are missing so is the distance: any value will do
                    c = np.where(np.isfinite(a[:, i]), a[:, i], a[:, j])
                    c = np.where(np.isfinite(c), c - np.nanmean(c), 0.0)
                    cols.append(c)
            A = np.stack(cols, axis=1)
            ok = np.isfinite(d) & keep[:, i] & keep[:, j]
            if ok.sum() < 2 * A.shape[1] + 3:
                A, cols = A[:, :1], cols[:1]
            if ok.sum() < 3:
                continue
            coef, *_ = np.linalg.lstsq(
                finite(A[ok], "the screening's drift design"),
                finite(d[ok], "the screening's distances"),
                rcond=None,
            )
            out[(i, j)] = d - A @ coef
    return out


def within_pose(r: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Each reading's residual (m, K, 3) minus the mean of its kept pose-mates', scaled to unit
    variance per axis for equal noise (the mean of n others adds 1/n); NaN without a kept mate."""
    kept = np.where(keep[..., None], r, 0.0)
    n = keep.sum(axis=1)[:, None] - keep  # kept mates of each reading
    mates = (kept.sum(axis=1, keepdims=True) - kept) / np.maximum(n, 1)[..., None]
    w = (r - mates) / np.sqrt(1.0 + 1.0 / np.maximum(n, 1))[..., None]
    w[n == 0] = np.nan
    return w


class _Judge:
    """The statistics of one round: residuals, scales and thresholds."""

    def __init__(self, r, meas, keep, time_s, temp_c, alpha, leverage=None):
        self.r = r
        # a reading the fit used pulled the fit toward itself: its residual, scaled by
        # 1/sqrt(1 - leverage), is what it would be were it left out (studentized)
        lev = np.zeros(r.shape[:2]) if leverage is None else np.where(keep, leverage, 0.0)
        self.rs = r / np.sqrt(1.0 - np.clip(lev, 0.0, 0.99))[..., None]
        self.have = np.all(np.isfinite(r), axis=-1)
        counts = self.have.sum(axis=1)
        multi = counts >= 2
        self.w = within_pose(r, keep & self.have)
        self.dist = distance_residuals(meas, keep & self.have, time_s, temp_c)
        n_multi = int(self.have[multi].sum())
        n_pairs = sum(int(np.isfinite(e).sum()) for e in self.dist.values())
        # a pose can leave one reading to the geometric test: a single one, or the last one left
        n_single = int((counts >= 1).sum())
        kinds = [
            k
            for k, n in (("within", n_multi), ("distance", n_pairs), ("geometric", n_single))
            if n > 0
        ]
        a = alpha / max(len(kinds), 1)
        chi3 = stats.chi(3)
        self.T = {
            "within": float(chi3.isf(a / max(n_multi, 1))),
            "distance": float(stats.norm.isf(a / (2 * max(n_pairs, 1)))),
            # the arm's own error at a pose may lie along a single direction (with all of
            # the three axes' variance): the worst case for a 3-D norm, a 1-D Gaussian
            "geometric": float(np.sqrt(3.0) * stats.norm.isf(a / (2 * max(n_single, 1)))),
        }
        self.s = {
            "within": _scale_1d(self.w[self.have].ravel()),
            "distance": _scale_1d(np.concatenate([e for e in self.dist.values()]))
            if self.dist
            else float("nan"),
            "geometric": _scale_1d(self.rs[self.have].ravel()),
        }

    def ratio_within(self, p, k, S) -> float:
        """How far reading k of pose p stands from its mates S (excluding k), over the threshold."""
        mates = [j for j in S if j != k]
        if not mates:
            return 0.0
        w = (self.r[p, k] - self.r[p, mates].mean(axis=0)) / np.sqrt(1.0 + 1.0 / len(mates))
        zw = np.linalg.norm(w) / self.s["within"] / self.T["within"]
        zd = (
            min(abs(self._pair(p, k, j)) for j in mates) / self.s["distance"] / self.T["distance"]
            if self.dist
            else 0.0
        )
        return float(max(zw, zd))

    def _pair(self, p, i, j) -> float:
        e = self.dist.get((min(i, j), max(i, j)))
        return 0.0 if e is None or not np.isfinite(e[p]) else float(e[p])

    def worst(self, p, S) -> float:
        return max((self.ratio_within(p, k, S) for k in S), default=0.0) if len(S) >= 2 else 0.0

    def geometric(self, p, k) -> float:
        return float(np.linalg.norm(self.rs[p, k]) / self.s["geometric"])

    def suspects(self) -> np.ndarray:
        """(m,) bool: the poses judge_pose may exclude from, found for all poses at once; those
        left out it would pass (a margin keeps borderline ones for the exact per-pose look)."""
        have, r = self.have, self.r
        counts = have.sum(axis=1)
        w = within_pose(r, have)  # each reading against all its pose's others present
        ratio = np.linalg.norm(w, axis=-1) / self.s["within"] / self.T["within"]
        if self.dist:
            K = have.shape[1]
            near = np.full(have.shape, np.inf)  # per reading, its smallest pair departure
            for i in range(K):
                for j in range(K):
                    if i == j:
                        continue
                    e = self.dist.get((min(i, j), max(i, j)))
                    d = np.zeros(len(r)) if e is None else np.where(np.isfinite(e), np.abs(e), 0.0)
                    near[:, i] = np.where(have[:, j], np.minimum(near[:, i], d), near[:, i])
            near[~np.isfinite(near)] = 0.0
            ratio = np.maximum(ratio, near / self.s["distance"] / self.T["distance"])
        worst = np.max(np.where(have, ratio, 0.0), axis=1)
        geo = np.linalg.norm(self.rs, axis=-1) / self.s["geometric"]
        single = np.max(np.where(have, geo, 0.0), axis=1)
        margin = 1.0 - 1e-6
        # NaN scales or thresholds compare false: such poses go to the exact look
        calm = (counts >= 2) & (worst <= margin) | (counts == 1) & (
            single <= self.T["geometric"] * margin
        )
        return ~(calm | (counts == 0))

    def judge_pose(self, p) -> dict[int, str]:
        """The readings of pose p to exclude, with the evidence for each."""
        S = [int(k) for k in np.flatnonzero(self.have[p])]
        out = {}
        while len(S) >= 2 and self.worst(p, S) > 1.0:
            # remove a reading whose removal leaves the others consistent; among several such
            # (two readings left), or when no single removal does (two bad readings), the one
            # the geometric model misses most
            def cost(k):
                rest = [j for j in S if j != k]
                return (self.worst(p, rest) > 1.0, -self.geometric(p, k))

            k = min(S, key=cost)
            zd = (
                (
                    min(abs(self._pair(p, k, j)) for j in S if j != k)
                    / self.s["distance"]
                    / self.T["distance"]
                )
                if self.dist
                else 0.0
            )
            out[k] = "distance" if zd > 1.0 else "within-pose"
            S.remove(k)
        if len(S) == 1 and self.geometric(p, S[0]) > self.T["geometric"]:
            out[S[0]] = "geometric"  # nothing else left to tell
        return out


def screen(fit, q, meas, time_s=None, temp_c=None, alpha=ALPHA, max_rounds=MAX_ROUNDS) -> Screening:
    """Iterated screening of a campaign's readings (m, K, 3) mm.

    fit(meas) -> (predictions (m, K, 3), leverage (m, K) or None) of a geometric model fitted to
    those readings (NaN = missing), e.g. an ls-sum calibration; it is called once per round.
    """
    meas = np.asarray(meas, dtype=float)
    have = np.all(np.isfinite(meas), axis=-1)
    excluded = np.zeros_like(have)
    evidence: dict = {}

    def residuals():
        m_now = meas.copy()
        m_now[excluded] = np.nan
        pred, lev = fit(m_now)
        return pred - meas, lev

    try:
        first = residuals()
    except NotIdentifiable as e:  # too few poses for the geometry: a nominal fit may still run
        return Screening(excluded, np.full(have.shape, np.nan), skipped=str(e))
    for rounds in range(1, max_rounds + 1):
        r, lev = first if rounds == 1 else residuals()
        judge = _Judge(r, meas, have & ~excluded, time_s, temp_c, alpha, lev)
        new = np.zeros_like(have)
        ev = {}
        for p in np.flatnonzero(judge.suspects()):
            for k, why in judge.judge_pose(int(p)).items():
                new[p, k] = True
                ev[(p, k)] = why
        if np.array_equal(new, excluded):
            break
        excluded, evidence = new, ev
    else:  # the set still moved on the last round: residuals of the set kept
        r, _ = residuals()
    return Screening(
        excluded,
        np.linalg.norm(r, axis=-1),
        evidence,
        {k: float(v) for k, v in judge.s.items()},
        {k: float(v) for k, v in judge.T.items()},
        rounds,
    )


def leverage(blocks: Callable[[], Iterable[np.ndarray]]) -> np.ndarray:
    """Per reading, the mean diagonal of its 3x3 block of the hat matrix of J (readings x 3, P);
    parameters the data cannot separate drop out with their null singular values.

    J comes as its row blocks, each call of `blocks` yielding them again: R of J's QR from the
    blocks, then the rows of U = J V / s from R's SVD, so the campaign's whole Jacobian (and U)
    is never held (140 MB each at 50,000 poses of three SMRs).
    """
    stacked = None
    for Jb in blocks():
        part = np.linalg.qr(finite(Jb, "the screening's Jacobian"), mode="r")
        stacked = part if stacked is None else np.linalg.qr(np.vstack([stacked, part]), mode="r")
    if stacked is None:
        return np.zeros(0)
    # columns scaled to unit norm, as J's are: ||J e_i|| = ||R e_i||, and R D is J D's R
    norms = np.maximum(np.linalg.norm(stacked, axis=0), 1e-300)
    _, sv, Vt = np.linalg.svd(stacked / norms)
    keep = sv > sv[0] * 1e-9 if sv.size and sv[0] > 0 else np.zeros(sv.shape, bool)
    W = Vt[keep].T / sv[keep]
    rows = [np.sum(((Jb / norms) @ W) ** 2, axis=1) for Jb in blocks()]
    return np.concatenate(rows).reshape(-1, 3).mean(axis=1)


def geometric_fit(problem: Problem):
    """fit(meas) for screen(): an ls-sum calibration's predictions and its readings' leverage."""
    from .calibrate import calibrate
    from .kinematics import predict, predict_rows

    q = problem.q

    def fit(meas):
        cal = calibrate(problem.with_meas(meas), "ls-sum")
        mask = np.all(np.isfinite(meas), axis=-1)
        cols = np.arange(cal.layout.n_params)
        starts = range(0, len(q), LEVERAGE_POSES)

        def blocks():
            for i in starts:
                b = slice(i, i + LEVERAGE_POSES)
                if mask[b].any():
                    _, Jt = predict_rows(cal.layout, cal.x, q[b], mask[b], cols)
                    yield Jt.reshape(len(cols), -1).T

        lev = np.zeros(mask.shape)
        lev[mask] = leverage(blocks)
        return predict(cal.layout, cal.x, q), lev

    return fit


def screen_readings(problem: Problem, alpha=ALPHA) -> Screening:
    """Screen a campaign with the geometric (ls-sum) model: the one call the commands make."""
    p = problem
    return screen(geometric_fit(p), p.q, p.meas, p.time_s, p.temp_c, alpha)
