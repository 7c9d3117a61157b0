"""What the geometric model gets wrong: candidate effects judged by cross-validated held-out error.

Forward selection: each round fits every candidate extension on top of the current model in every
fold, and accepts the best only when its held-out gain over the current model is significant by a
paired test over poses; the simplest candidate that is not significantly worse than the best is
preferred, so that a cyclic error is not called compliance merely because compliance has more
parameters. Clean data and real data thus get no effect that does not pay off on unseen poses.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import identifiability as ident
from .effects import Extension, Inputs, gravity_basis, gravity_in_base, select_independent
from .extended import fit_extended, predict_extended
from .identify import Problem, register
from .kinematics import predict_rows
from .robot import Robot

T_CRIT = 4.0  # paired t over poses needed to accept an effect
MIN_GAIN = 0.05  # and at least this fraction of held-out mean squared error removed
T_SIMPLER = 2.0  # a simpler candidate wins unless the best beats it by this paired t
MAX_EFFECTS = 4
FOLDS = 5
EDGE_POSES = 5  # a base shift must leave at least this many poses on either side


@dataclass
class CV:
    """Held-out residuals of one model over all folds."""

    sq: np.ndarray  # (m,) per pose: sum over its readings of squared held-out error
    n: np.ndarray  # (m,) readings per pose
    maxerr: float
    exts: list  # extensions as fitted on all data (with coefficients)
    fits: dict = field(default_factory=dict)  # fold (or "all") -> (x, extensions) fitted there
    resid: np.ndarray | None = None  # (m, K, 3) held-out residual (prediction - reading), NaN if missing

    @property
    def mse(self) -> float:
        return float(self.sq.sum() / self.n.sum())

    @property
    def rmse(self) -> float:
        return float(np.sqrt(self.mse))


@dataclass
class Diagnosis:
    """The report (FORMATS.md section 5), the final model and the data behind the figures."""

    report: dict
    layout: object
    x: np.ndarray
    extensions: list
    parameters: list  # per extension, in edge units
    figures: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)


def noise_floor(meas: np.ndarray, inputs: Inputs) -> float | None:
    """Tracker noise (3-D RMS) from the spread of SMR-to-SMR distances, which no model error changes.

    Each distance's error is the difference of two readings' noise along the pair, of variance
    2 sigma^2; trends with temperature and time (thermal growth) are removed first.
    """
    K = meas.shape[1]
    var = []
    for i in range(K):
        for j in range(i + 1, K):
            d = np.linalg.norm(meas[:, i] - meas[:, j], axis=-1)
            cols = [np.ones_like(d)]
            for a in (inputs.temp_c, inputs.time_s):
                if a is not None:
                    cols.append(np.nanmean(a[:, [i, j]], axis=1))
            A = np.stack(cols, axis=1)
            ok = np.isfinite(d) & np.all(np.isfinite(A), axis=1)
            if ok.sum() < 10:
                continue
            coef, *_ = np.linalg.lstsq(A[ok], d[ok], rcond=None)
            r = d[ok] - A[ok] @ coef
            var.append(np.sum(r * r) / (ok.sum() - A.shape[1]) / 2.0)
    return float(np.sqrt(3.0 * np.mean(var))) if var else None


def folds(m: int, k: int = FOLDS, seed: int = 0) -> list[np.ndarray]:
    perm = np.random.default_rng(seed).permutation(m)
    return [np.sort(perm[i::k]) for i in range(k)]


def candidates(layout, x, inputs: Inputs) -> list[Extension]:
    """Every effect of the vocabulary that this data could show, per joint and harmonic."""
    n = layout.robot.n_joints
    out = []
    for j in range(n):
        out += [Extension("joint_periodic", joint=j, harmonic=1),
                Extension("joint_periodic", joint=j, harmonic=2),
                Extension("joint_scale", joint=j)]
    g = gravity_in_base(layout, x)
    for j in range(n):
        keep = select_independent(gravity_basis(layout, x, inputs.q, j, g))
        if keep.any():
            out.append(Extension("joint_compliance", joint=j, keep=keep, gravity=g))
    if inputs.temp_c is not None and np.nanmax(inputs.temp_c) - np.nanmin(inputs.temp_c) >= 0.3:
        out.append(Extension("thermal_drift", variable="temp_c",
                             t_ref=float(np.nanmean(inputs.temp_c))))
    elif inputs.time_s is not None:
        out.append(Extension("thermal_drift", variable="time_s",
                             t_ref=float(np.nanmean(inputs.time_s))))
    if inputs.time_s is not None and np.isfinite(inputs.time_s).any():
        out.append(Extension("base_shift"))
    return out


class Diagnoser:
    """Cross-validation of model variants on one campaign."""

    def __init__(self, prob: Problem, x0, free, inputs: Inputs, k_folds=FOLDS):
        self.prob, self.x0, self.free, self.inputs = prob, x0, free, inputs
        self.folds = folds(prob.q.shape[0], k_folds)
        self.centroid = np.nanmean(prob.meas.reshape(-1, 3), axis=0)
        self.fits = 0
        self.warm: dict = {}  # fold -> (x, extensions) of the current model, to start fits from

    def _with_shift_time(self, exts):
        """Base-shift extensions get their time from a scan of all poses; others pass.

        The change time is located once on the whole campaign and then held in every fold. Were
        it located per fold, a held-out pose between the two training poses around the shift
        would fall on either side by a coin flip, however clear the shift: no training reading
        says on which side of it the unseen pose lies. The shift itself is fitted per fold and
        judged on the held-out poses like every other extension.
        """
        out = []
        for e in exts:
            if e.name == "base_shift" and e.at_s is None:
                e = Extension("base_shift", at_s=self.scan_shift(
                    [o for o in exts if o is not e], np.arange(self.prob.q.shape[0])),
                    origin=self.centroid)
            out.append(e)
        return out

    def fit(self, exts, poses=None, fold="all"):
        self.fits += 1
        poses = np.arange(self.prob.q.shape[0]) if poses is None else poses
        start = None
        if fold in self.warm:
            # the current model's fit on the same poses: only the new extension starts from zero
            start, known = self.warm[fold]
            exts = [Extension(**{**e.__dict__, "coef": k.coef}) if i < len(known) else e
                    for i, (e, k) in enumerate(zip(exts, known + [None] * len(exts)))]
        x, ee, _ = fit_extended(self.prob, self.inputs, self.x0, self.free, exts, poses,
                                start=start)
        return x, ee

    def residuals(self, x, exts, poses):
        sub = self.inputs.subset(poses)
        return predict_extended(self.prob.layout, x, exts, sub) - self.prob.meas[poses]

    def cross_validate(self, exts) -> CV:
        m = self.prob.q.shape[0]
        exts = self._with_shift_time(exts)
        sq, n = np.zeros(m), np.zeros(m)
        resid = np.full(self.prob.meas.shape, np.nan)
        maxerr = 0.0
        fits = {}
        for f, test in enumerate(self.folds):
            train = np.setdiff1d(np.arange(m), test)
            x, ee = self.fit(exts, train, fold=f)
            fits[f] = (x, ee)
            r = self.residuals(x, ee, test)
            resid[test] = r
            e2 = np.sum(r * r, axis=-1)
            sq[test] = np.nansum(e2, axis=1)
            n[test] = np.sum(np.isfinite(e2), axis=1)
            maxerr = max(maxerr, float(np.sqrt(np.nanmax(e2))))
        x, ee = self.fit(exts)
        fits["all"] = (x, ee)
        return CV(sq, n, maxerr, ee, fits, resid)

    def scan_shift(self, others, poses) -> float:
        """The time of a base shift that best explains the training residuals (linearised).

        Every gap between two consecutive readings is a candidate (a shift may fall between the
        SMRs of one pose). For each, the gain of the six shift columns, made orthogonal to the
        geometric Jacobian, is b' (Z'Z)^-1 b; all the Gram sums are suffix sums over readings in
        time order, so the whole scan costs about one Jacobian.
        """
        x, ee = self.fit_plain(others, poses)
        sub = self.inputs.subset(poses)
        meas = self.prob.meas[poses]
        mask = np.all(np.isfinite(meas), axis=-1) & np.isfinite(sub.time_s)
        r = predict_extended(self.prob.layout, x, ee, sub)[mask] - meas[mask]  # (N, 3)
        idx = np.flatnonzero(self.free)
        _, Jt = predict_rows(self.prob.layout, x, sub.q, mask, idx)  # (P, N, 3)
        Q, _ = np.linalg.qr(Jt.reshape(len(idx), -1).T)
        Q = Q.reshape(-1, 3, Q.shape[1])  # (N, 3, P)
        t = sub.time_s[mask]
        order = np.argsort(t, kind="stable")
        t, r, Q = t[order], r[order], Q[order]
        v = meas[mask][order] - self.centroid
        Z = np.zeros((len(t), 3, 6))  # per reading: translation and rotation columns
        Z[:, [0, 1, 2], [0, 1, 2]] = 1.0
        for a in range(3):
            e = np.zeros(3)
            e[a] = 1.0
            Z[:, :, 3 + a] = np.cross(e, v)
        suffix = lambda a: np.cumsum(a[::-1], axis=0)[::-1]  # noqa: E731
        ZZ = suffix(np.einsum("nci,ncj->nij", Z, Z))
        QZ = suffix(np.einsum("ncp,nci->npi", Q, Z))
        Zr = suffix(np.einsum("nci,nc->ni", Z, r))
        Qr = np.einsum("ncp,nc->p", Q, r)
        lo = EDGE_POSES * meas.shape[1]
        best, best_at = -1.0, float(np.median(t))
        for n in range(max(lo, 1), len(t) - lo):
            if t[n] == t[n - 1]:
                continue
            G = ZZ[n] - QZ[n].T @ QZ[n]
            b = Zr[n] - QZ[n].T @ Qr
            try:
                gain = float(b @ np.linalg.solve(G + 1e-12 * np.trace(G) * np.eye(6), b))
            except np.linalg.LinAlgError:
                continue
            if gain > best:
                best, best_at = gain, 0.5 * float(t[n - 1] + t[n])
        return best_at

    def fit_plain(self, exts, poses):
        x, ee, _ = fit_extended(self.prob, self.inputs, self.x0, self.free, exts, poses)
        return x, ee


def paired_t(a: np.ndarray, b: np.ndarray) -> float:
    """t statistic of the per-pose reduction a - b (positive when b is better)."""
    d = a - b
    sd = d.std(ddof=1)
    if sd == 0:
        return float("inf") if d.mean() > 0 else 0.0
    return float(d.mean() / (sd / np.sqrt(len(d))))


def select(diag: Diagnoser, cands, log=None):
    """Forward selection; returns the accepted steps [(extension, cv_before, cv_after, t)] and final CV."""
    current: list[Extension] = []
    cv_now = diag.cross_validate(current)
    diag.warm = cv_now.fits
    base = cv_now
    steps = []
    remaining = list(cands)
    while remaining and len(steps) < MAX_EFFECTS:
        scored = []
        for c in remaining:
            cv = diag.cross_validate(current + [c])
            scored.append((c, cv, paired_t(cv_now.sq, cv.sq)))
            if log:
                log(f"  {c.label()}: held-out RMS {cv.rmse:.4f} mm (t = {scored[-1][2]:.1f})")
        ok = [s for s in scored if s[2] > T_CRIT and s[1].mse < (1 - MIN_GAIN) * cv_now.mse]
        if not ok:
            break
        best = min(ok, key=lambda s: s[1].mse)
        peers = [s for s in ok if paired_t(s[1].sq, best[1].sq) < T_SIMPLER]
        pick = min(peers, key=lambda s: (s[0].n_params, s[1].mse))
        c, cv, t = pick
        steps.append((cv.exts[-1], cv_now, cv, t))
        current = current + [cv.exts[-1] if c.name != "base_shift" else
                             Extension("base_shift", at_s=cv.exts[-1].at_s, origin=diag.centroid)]
        # the same joint's other candidates of the same kind stay: two effects may share a joint
        remaining = [r for r in remaining if not (r.name == c.name and r.joint == c.joint
                                                  and r.harmonic == c.harmonic)]
        if c.name in ("thermal_drift", "base_shift"):
            remaining = [r for r in remaining if r.name != c.name]
        cv_now = cv
        diag.warm = cv.fits
    return steps, base, cv_now


def diagnose(robot: Robot, targets, target_names, q, meas, time_s=None, temp_c=None,
             base_guess=None, log=None) -> Diagnosis:
    """Baseline geometric calibration, candidate effects, selection and the extended model."""
    t0 = time.perf_counter()
    clock = {}
    prob, x0 = register(robot, targets, target_names, q, meas, base_guess)
    st = ident.structural(prob.layout, x0, np.ones(prob.layout.n_params, dtype=bool))
    J = ident.jacobian_rows(prob.layout, x0, q, prob.mask)
    ident.check_data(ident.gram(J, st.free), st.free, prob.layout.names(), J.shape[0], q.shape[0])
    inputs = Inputs(q, time_s, temp_c)
    clock["setup"] = time.perf_counter() - t0
    diag = Diagnoser(prob, x0, st.free, inputs)
    cands = candidates(prob.layout, x0, inputs)
    t1 = time.perf_counter()
    steps, base, final = select(diag, cands, log)
    clock["selection"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    exts = [s[0] for s in steps]
    x, ee = diag.fit(exts)
    clock["final_fit"] = time.perf_counter() - t2
    floor = noise_floor(meas, inputs)
    from .diagnosis_report import build_report, figure_series

    params, report = build_report(diag, steps, base, final, ee, x, floor, len(cands))
    figures = figure_series(diag, steps, ee, x)
    from .unexplained import unexplained

    left = unexplained(final.resid, prob.layout, x, ee, inputs, floor, base.mse)
    if left is not None:
        report["unexplained"] = left
    clock["total"] = time.perf_counter() - t0
    report["seconds"] = {k: round(v, 3) for k, v in clock.items()}
    report["cross_validation"] = {"folds": len(diag.folds), "fits": diag.fits,
                                  "candidates": len(cands)}
    return Diagnosis(report, prob.layout, x, ee, params, figures, clock)
