"""What the final model leaves unexplained, and what that remainder depends on.

When the final model's held-out RMS stays well above the tracker's noise floor, the remaining
held-out residual is regressed, one covariate at a time, on a small basis of that covariate (each
joint's angle, the direction of its last motion, the gravity torque about it, time, temperature,
distance from the tracker) carried to the SMRs through one channel: a joint's rotation (the joint
column of the Jacobian) or a rigid Cartesian displacement. Every field is first made orthogonal to
what the fitted model can absorb (its geometric Jacobian and its extensions), so a covariate gets
credit only for error the model cannot take.

A covariate's strength is the cross-validated share of the remaining residual that its best channel
explains on poses left out of the regression: 1 - (held-out squared error) / (squared residual),
clipped at 0. Fitting noise raises the error on unseen poses instead of lowering it, so on clean data
strengths stay near 0 whatever the basis size; the per-pose folds keep the SMRs of one pose together,
so a per-pose error (repeatability) cannot be fitted and then counted as explained.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .effects import Extension, Inputs, joint_basis, point_basis, point_shift
from .finite import finite
from .gravity import gravity_basis, gravity_in_base
from .kinematics import Layout, joint_frames, predict_rows
from .noise import DISTANCES, REPEATS

ABOVE_FLOOR = 1.5  # held-out RMS over the noise floor above which the remainder is reported
STRONG = 0.1  # a covariate explaining at least this share of the remainder is worth a look
DOMINANT = 0.5  # the per-pose shared error dominates above this share of the remainder
MAX_COVARIATES = 5
FOLDS = 10
ANGLE_DEGREE = 3  # Legendre terms of a joint angle: scale, bow and the S of a low harmonic
SCALAR_DEGREE = 2  # of time, temperature and distance: drift and its curvature
GRAVITY_TERMS = 3  # principal components of a joint's gravity-torque basis
VERTICAL_DEG = 5.0  # a joint axis never further than this from vertical carries no gravity torque
TRAINED = 0.8  # share of the readings each fold's fit saw (the diagnosis's 5-fold cross-validation)
NULL_DRAWS = 19  # random deals of the covariates: beating all of them is a 5% test
OWN_TIE = 0.9  # a joint's own channel is preferred when it explains this fraction of the best one
# Below ABOVE_FLOOR x a stated floor (a tracker spec the readings may beat), a covariate must
# explain at least this share of the remainder (as much as noise leaves) for the block: at STRONG
# it appeared on 1 of 36 clean one-SMR campaigns under a 5x spec (IRB 120, seed 0, 40 poses)
STRONG_BELOW_STATED = 0.5


def unexplained(
    resid: np.ndarray,
    layout: Layout,
    x,
    extensions: list[Extension],
    inputs: Inputs,
    floor: float | None,
    baseline_mse: float,
    floor_source: str = DISTANCES,
) -> dict | None:
    """The `unexplained` block of the report (FORMATS.md section 5), or None when nothing is left.

    resid: (m, K, 3) held-out residual of the final model (prediction - reading), NaN if missing.
    With a noise floor the block appears whenever the held-out RMS exceeds ABOVE_FLOOR times the
    floor (the rule a user reads in the report); `reachable_mm` says what a correct model
    reaches held out (the floor, raised by the noise its P fitted columns carry to unseen
    readings, sqrt(1 + P / readings fitted), as for any least-squares prediction), so a small
    campaign's remainder can be read against it. With none (one SMR a pose) the floor cannot tell
    noise from error, so the block appears only when some covariate explains at least STRONG of
    the remainder on left-out poses and more than any of NULL_DRAWS random deals of the
    covariates to the readings does (`chance_strength`). A floor not measured in the data
    (floor_source: solver.noise's; the tracker's specification) may overstate the readings'
    noise and hide the remainder below ABOVE_FLOOR times it: there the data alone decides, as
    without one, a covariate explaining at least STRONG_BELOW_STATED of the remainder.
    """
    mask = np.all(np.isfinite(resid), axis=-1)
    r = resid[mask]  # (N, 3)
    if len(r) == 0:
        return None
    rmse = float(np.sqrt(np.mean(np.sum(r * r, axis=-1))))
    below = floor is not None and rmse <= ABOVE_FLOOR * floor
    if below and floor_source in (DISTANCES, REPEATS):
        return None
    pose = np.nonzero(mask)[0]
    fields = Fields(layout, x, extensions, inputs, mask)
    reach = None if floor is None else floor * np.sqrt(1.0 + fields.Q.shape[1] / (TRAINED * r.size))
    cands = candidate_covariates(fields)
    covs = ranked(fields, r, pose, cands, MAX_COVARIATES)
    chance = None
    if floor is None or below:
        if not covs or covs[0]["strength"] < (STRONG_BELOW_STATED if below else STRONG):
            return None
        chance = chance_strength(fields, r, pose, cands)
        if covs[0]["strength"] <= chance:
            return None
    block: dict[str, Any] = {
        "holdout_rmse_mm": rmse,
        "share_of_baseline_mse": float(rmse**2 / baseline_mse) if baseline_mse > 0 else None,
        "noise_floor_ratio": None if not floor else rmse / floor,
        "reachable_mm": reach,
        "covariates": covs,
    }
    if chance is not None:
        block["chance_strength"] = chance
    shared = per_pose_share(r, fields.p, pose, floor)
    if shared is not None:
        block["per_pose_share"] = shared
        top = covs[0]["strength"] if covs else 0.0
        block["per_pose_dominates"] = bool(shared >= DOMINANT and top < 0.5 * shared)
        block["per_pose_reading"] = per_pose_reading(shared, block["per_pose_dominates"])
    block["reading"] = summary(block, floor)
    return block


class Fields:
    """The displacement fields of one data set: joint columns, rigid motions, and what the fitted
    model absorbs (an orthonormal basis Q of its Jacobian's range)."""

    def __init__(self, layout: Layout, x, extensions, inputs: Inputs, mask):
        self.layout, self.x, self.inputs, self.mask = layout, x, inputs, mask
        self.pose = np.nonzero(mask)[0]
        bases = [
            joint_basis(e, layout, x, inputs) if e.is_joint else point_basis(e, layout, x, inputs)
            for e in extensions
        ]
        dq = None
        for e, B in zip(extensions, bases):
            if e.is_joint:
                dq = np.zeros_like(inputs.q) if dq is None else dq
                dq[:, e.joint] += B @ e.coef
        p, Jt, Jq = predict_rows(
            layout, x, inputs.q, mask, np.arange(layout.n_params), dq=dq, joint_cols=True
        )
        self.p, self.Jq = p, Jq  # (N, 3), (n, N, 3)
        self.centroid = p.mean(axis=0)
        cols = [Jt.reshape(Jt.shape[0], -1).T]
        for e, B in zip(extensions, bases):
            if e.is_joint:
                cols.append(
                    (Jq[e.joint][None] * B[self.pose].T[:, :, None]).reshape(B.shape[1], -1).T
                )
            else:
                origin = layout.base(x)[:3, 3] if e.name == "thermal_drift" else e.origin
                s = np.nan_to_num(B[mask])
                _, J = point_shift(e, s, p, origin if origin is not None else self.centroid)
                cols.append(J.reshape(J.shape[0], -1).T)
        A = np.concatenate(cols, axis=1)
        U, sv, _ = np.linalg.svd(finite(A, "the residual basis"), full_matrices=False)
        self.Q = U[:, sv > 1e-9 * sv[0]]

    def channels(self, kind: str) -> list[tuple[str, np.ndarray]]:
        """Per channel, its name and unit fields (c, N, 3): a joint's rotation or a rigid motion;
        for the distance from the tracker, a stretch along the beam or a rigid motion."""
        v = self.p - self.centroid
        rigid = np.zeros((6,) + self.p.shape)
        for a in range(3):
            e = np.zeros(3)
            e[a] = 1.0
            rigid[a, :, a] = 1.0
            rigid[3 + a] = np.cross(e, v) / 1000.0  # per metre of lever: columns of like size
        if kind == "distance":
            beam = self.p / np.linalg.norm(self.p, axis=1, keepdims=True)
            return [("beam", beam[None]), ("rigid", rigid)]
        return [(f"joint {j + 1}", self.Jq[j][None]) for j in range(self.Jq.shape[0])] + [
            ("rigid", rigid)
        ]

    def design(self, basis: np.ndarray, unit: np.ndarray) -> np.ndarray:
        """Columns (3N, P c) of basis (N, P) times each unit field, made orthogonal to the model."""
        F = (basis.T[:, None, :, None] * unit[None]).reshape(-1, unit.shape[1] * 3).T
        F = F - self.Q @ (self.Q.T @ F)
        norms = np.linalg.norm(F, axis=0)
        keep = norms > 1e-9 * max(norms.max(), 1e-300)
        return F[:, keep] / norms[keep]


def legendre(v: np.ndarray, degree: int) -> np.ndarray | None:
    """(len(v), degree) Legendre terms of v mapped onto [-1, 1], centred; None if v is constant.
    Missing values (NaN) get 0, the mean."""
    ok = np.isfinite(v)
    if ok.sum() < 3 or np.ptp(v[ok]) <= 0:
        return None
    lo, hi = np.min(v[ok]), np.max(v[ok])
    u = np.where(ok, 2.0 * (v - lo) / (hi - lo) - 1.0, 0.0)
    B = np.polynomial.legendre.legvander(u, degree)[:, 1:]
    B = B - B[ok].mean(axis=0)
    B[~ok] = 0.0
    return B


def gravity_terms(G: np.ndarray) -> np.ndarray:
    """The few principal components of a joint's gravity-torque basis G (m, c): the shapes its
    torque can take whatever the unknown masses."""
    G = G - G.mean(axis=0)
    scale = np.linalg.norm(G, axis=0)
    live = scale > 1e-9 * scale.max()
    U, sv, _ = np.linalg.svd(
        finite(G[:, live] / scale[live], "the residual design"), full_matrices=False
    )
    share = np.cumsum(sv**2) / np.sum(sv**2)
    return U[:, : min(GRAVITY_TERMS, int(np.searchsorted(share, 0.99)) + 1)]


def candidate_covariates(fields: Fields):
    """[(key, name, basis (N, P))] of every covariate this data can show."""
    inputs, mask, pose = fields.inputs, fields.mask, fields.pose
    out: list[tuple[tuple[str, int | None], str, np.ndarray]] = []
    n = inputs.q.shape[1]
    for j in range(n):
        B = legendre(inputs.q[:, j], ANGLE_DEGREE)
        if B is not None:
            out.append((("angle", j), f"joint {j + 1}'s angle", B[pose]))
    assert inputs.motion is not None  # Inputs fills it in from q when not given
    for j in range(n):
        s = inputs.motion[:, j].astype(float)
        if np.ptp(s) > 0:
            out.append(
                (
                    ("motion", j),
                    f"direction of joint {j + 1}'s last motion",
                    (s - s.mean())[pose, None],
                )
            )
    g = gravity_in_base(fields.layout, fields.x)
    frames = joint_frames(Layout(fields.layout.robot, np.eye(4), ()), fields.x, inputs.q)
    for j in range(n):
        # an axis that stays vertical carries no gravity torque: its basis would hold only the
        # base's tilt, a shape of the pose with nothing of gravity in it
        if np.abs(frames[j][0][:, :, 2] @ g).min() < np.cos(np.radians(VERTICAL_DEG)):
            G = gravity_basis(fields.layout, fields.x, inputs.q, j, g)
            out.append(
                (("gravity", j), f"gravity torque about joint {j + 1}", gravity_terms(G)[pose])
            )
    for key, a, name in (
        ("time", inputs.time_s, "time"),
        ("temperature", inputs.temp_c, "air temperature"),
    ):
        if a is not None:
            B = legendre(np.asarray(a, dtype=float)[mask], SCALAR_DEGREE)
            if B is not None:
                out.append(((key, None), name, B))
    B = legendre(np.linalg.norm(fields.p, axis=1), SCALAR_DEGREE)
    if B is not None:
        out.append((("distance", None), "distance from the tracker", B))
    return out


def covariates(
    fields: Fields, r: np.ndarray, pose: np.ndarray, shuffle=None, cands=None
) -> list[dict]:
    """Every covariate with its strength (best channel's cross-validated share) and a reading."""
    held = HeldOut(fields.Q, r.ravel(), pose_folds(pose))
    return [
        entry
        for entry, _ in scored(fields, held, held, cands or candidate_covariates(fields), shuffle)
    ]


def ranked(fields: Fields, r: np.ndarray, pose: np.ndarray, cands, count: int) -> list[dict]:
    """The `count` covariates the remainder depends on most, greedily: each after the first is
    judged beside those above it, its strength the further share it removes, so that a covariate
    that only echoes a stronger one (a joint's motion direction follows its angle) drops back."""
    y, folds = r.ravel(), pose_folds(pose)
    first = HeldOut(fields.Q, y, folds)
    held, taken = first, fields.Q
    out: list[dict] = []
    left = list(cands)
    while left and len(out) < count:
        results = scored(fields, held, first, left, further=bool(out))
        if not results:
            break
        k = max(range(len(results)), key=lambda i: results[i][0]["strength"])
        entry, F = results[k]
        out.append(entry)
        if entry["strength"] < STRONG:  # nothing much left to take: the rest in this round's order
            rest = sorted(
                (e for i, (e, _) in enumerate(results) if i != k), key=lambda e: -e["strength"]
            )
            out += rest[: count - len(out)]
            break
        left = [c for c in left if c[1] != entry["name"]]
        taken = np.concatenate([taken, F], axis=1)
        held = HeldOut(taken, y, folds)
    return out


def scored(fields: Fields, held: HeldOut, first: HeldOut, cands, shuffle=None, further=False):
    """Per covariate, its entry and its best channel's design: the share of first.base that the
    design removes from what `held` leaves.

    A joint's own channel wins unless another explains clearly more (OWN_TIE): neighbouring
    parallel axes give nearly the same field, and the simpler cause is the joint's own error.
    """
    out = []
    for (kind, j), name, basis in cands:
        if shuffle is not None:  # a null draw: the covariate's values dealt to other readings
            basis = basis[shuffle]
        shares, designs = {}, {}
        for chan, unit in fields.channels(kind):
            F = fields.design(basis, unit)
            if F.shape[1]:
                designs[chan] = F
                shares[chan] = (held.base - held.error(F)) / first.base
        if not shares:
            continue
        where = max(shares, key=shares.__getitem__)
        own = None if j is None else f"joint {j + 1}"
        if own in shares and shares[own] >= OWN_TIE * shares[where]:
            where = own
        best = max(shares[where], 0.0)
        out.append(
            (
                {
                    "name": name,
                    "strength": round(float(best), 4),
                    "channel": where,
                    "reading": reading(kind, j, where, best, further),
                },
                designs[where],
            )
        )
    return out


def chance_strength(fields: Fields, r: np.ndarray, pose: np.ndarray, cands) -> float:
    """The largest strength that covariates dealt at random to the readings reach, over NULL_DRAWS
    draws: what the best of so many covariates and channels scores by chance on this campaign."""
    rng = np.random.default_rng(0)
    best = 0.0
    for _ in range(NULL_DRAWS):
        covs = covariates(fields, r, pose, shuffle=rng.permutation(len(r)), cands=cands)
        best = max([best] + [c["strength"] for c in covs])
    return round(best, 4)


def pose_folds(pose: np.ndarray) -> np.ndarray:
    """Per coordinate of each reading (3N,), its fold: whole poses are left out together."""
    poses = np.unique(pose)
    k = min(FOLDS, len(poses))
    fold_of = np.empty(pose.max() + 1, dtype=int)
    fold_of[poses] = np.random.default_rng(0).permutation(len(poses)) % k
    return np.repeat(fold_of[pose], 3)


class HeldOut:
    """Held-out squared error of least-squares fits on [Q, F] over pose folds, for many F.

    Q (what the model absorbs) is refitted in every fold alongside F, so a small campaign's own
    fitting noise is charged to neither side; its per-fold normal equations are solved once and
    each F then costs only its own small Schur complement.
    """

    def __init__(self, Q: np.ndarray, y: np.ndarray, folds: np.ndarray):
        self.Q, self.y = Q, y
        self.tests = [folds == f for f in np.unique(folds)]
        self.QtQ, self.Qty = Q.T @ Q, Q.T @ y
        self.parts = []
        for t in self.tests:
            Qt = Q[t]
            inv = np.linalg.pinv(finite(self.QtQ - Qt.T @ Qt, "the held-out Gram matrix"))
            self.parts.append((inv, inv @ (self.Qty - Qt.T @ y[t])))
        self.base = self.error(None)

    def error(self, F: np.ndarray | None) -> float:
        """Sum over folds of the squared held-out error of y by Q (and F) fitted on the others."""
        err = 0.0
        if F is not None:
            QF, FF, Fy = self.Q.T @ F, F.T @ F, F.T @ self.y
        for t, (inv, cq) in zip(self.tests, self.parts):
            Qt, yt = self.Q[t], self.y[t]
            pred = Qt @ cq
            if F is not None:
                Ft = F[t]
                Gqf = QF - Qt.T @ Ft
                S = FF - Ft.T @ Ft - Gqf.T @ inv @ Gqf
                cf = np.linalg.lstsq(
                    finite(S, "the held-out system"), Fy - Ft.T @ yt - Gqf.T @ cq, rcond=1e-10
                )[0]
                pred = Qt @ (cq - inv @ (Gqf @ cf)) + Ft @ cf
            e = yt - pred
            err += float(e @ e)
        return err

    def share(self, F: np.ndarray) -> float:
        """The share of the held-out error left by Q alone that adding F removes (negative when F
        only chases noise)."""
        return 1.0 - self.error(F) / self.base


def per_pose_share(r: np.ndarray, p: np.ndarray, pose: np.ndarray, floor: float | None):
    """Share of the remainder that one rigid motion per pose takes beyond what tracker noise alone
    would give it (noise of variance floor^2 / 3 per coordinate fills rank-many directions a pose),
    over the poses with two SMRs or more; None without a floor or without such a pose."""
    if floor is None:
        return None
    took, dims, total = 0.0, 0, 0.0
    for i in np.unique(pose):
        sel = pose == i
        if sel.sum() < 2:
            continue
        total += float(np.sum(r[sel] ** 2))
        v = p[sel] - p[sel].mean(axis=0)
        A = np.zeros((sel.sum(), 3, 6))
        for a in range(3):
            e = np.zeros(3)
            e[a] = 1.0
            A[:, a, a] = 1.0
            A[:, :, 3 + a] = np.cross(e, v)
        A = A.reshape(-1, 6)
        U, sv, _ = np.linalg.svd(finite(A, "the residual basis"), full_matrices=False)
        U = U[:, sv > 1e-9 * sv[0]]
        proj = U.T @ r[sel].ravel()
        took += float(proj @ proj)
        dims += U.shape[1]
    if dims == 0:
        return None
    return round(float(max(took - dims * floor**2 / 3.0, 0.0) / total), 4)


def reading(kind: str, j: int | None, channel: str, strength: float, further=False) -> str:
    """One line an engineer can act on: what the remainder follows, and where to look (further:
    the share is beyond the covariates listed above)."""
    J = None if j is None else j + 1
    own = channel == f"joint {J}"
    pct = f"{'a further ' if further else ''}{100 * strength:.0f}% of the remaining residual"
    if strength < STRONG:
        how = {"rigid": "a rigid displacement", "beam": "the beam direction"}.get(channel, channel)
        return f"weak: {pct} follows it on left-out poses (through {how})."
    if kind == "motion":
        if own:
            return f"the residual flips with the direction of joint {J}'s last motion ({pct}): backlash or lost motion in joint {J}?"
        if channel == "rigid":
            return (
                f"the SMRs shift as a whole with the direction of joint {J}'s last motion ({pct}): "
                f"hysteresis or backlash near joint {J}, or the arm settling after moves?"
            )
        return (
            f"{channel}'s error flips with the direction of joint {J}'s last motion ({pct}): "
            f"backlash or friction coupled between joints {J} and {channel.split()[1]}?"
        )
    if kind == "angle":
        assert J is not None  # an angle covariate belongs to a joint
        if own:
            return (
                f"joint {J}'s error follows its own angle beyond the modelled terms ({pct}): "
                f"a transmission or encoder error of higher order in joint {J}?"
            )
        if channel == "rigid":
            return (
                f"the SMRs move with joint {J}'s angle in a way no joint rotation explains ({pct}): "
                f"a bent or tilting axis, or link deflection, at joint {J}?"
            )
        other = int(channel.split()[1])
        return (
            f"{channel}'s error follows joint {J}'s angle ({pct}): a coupling between joints {J} "
            f"and {other}" + (" (a wrist gear coupling)?" if min(J, other) >= 4 else "?")
        )
    if kind == "gravity":
        if own:
            return (
                f"joint {J}'s error follows the gravity torque it carries ({pct}): compliance "
                f"in joint {J} that the model does not hold?"
            )
        if channel == "rigid":
            return (
                f"the SMRs sag with the gravity torque about joint {J} ({pct}): links bending, "
                f"or compliance across joint {J}'s axis?"
            )
        return (
            f"{channel}'s error follows the gravity torque about joint {J} ({pct}): compliance "
            f"in {channel}, loaded by the arm beyond joint {J}?"
        )
    what = {
        "time": "time",
        "temperature": "the air temperature",
        "distance": "the distance from the tracker",
    }[kind]
    if kind == "distance" and channel == "beam":
        return (
            f"the error along the beam grows with the distance from the tracker ({pct}): a "
            f"tracker distance scale error, or the air's refractive index mis-set?"
        )
    if kind == "distance":
        return (
            f"the SMRs move with the distance from the tracker ({pct}): a tracker angle-encoder "
            f"or levelling error, or a pose-dependent effect that tracks distance?"
        )
    if channel == "rigid":
        return (
            f"the SMRs drift with {what} ({pct}): thermal growth or the tracker or robot base "
            f"moving during the campaign?"
        )
    return (
        f"{channel}'s error drifts with {what} ({pct}): the drive or encoder of {channel} warming?"
    )


def per_pose_reading(share: float, dominates: bool) -> str:
    pct = f"{100 * share:.0f}% of the remaining residual"
    if dominates:
        return (
            f"{pct} moves all SMRs of a pose together, beyond tracker noise, and no covariate "
            f"explains it: the arm's repeatability, or poses measured before it settled?"
        )
    return f"{pct} moves all SMRs of a pose together beyond tracker noise (an error of the arm, not of the tracker)."


def summary(block: dict, floor: float | None) -> str:
    """One line: how much is left and where to look first."""
    left = f"{block['holdout_rmse_mm']:.3f} mm held out"
    if floor and block.get("chance_strength") is not None:  # a stated floor the data beats
        left += (
            f" ({block['noise_floor_ratio']:.1f}x the stated noise floor, which may overstate "
            f"the readings' noise; chance level of a strength {block['chance_strength']:.2f})"
        )
    elif floor:
        left += f" ({block['noise_floor_ratio']:.1f}x the noise floor)"
    elif floor is not None:  # noise-free readings: a floor, not an unknown one
        left += " (the noise floor is 0 mm)"
    else:
        left += f" (noise floor unknown; chance level of a strength {block['chance_strength']:.2f})"
    share = block["share_of_baseline_mse"]
    if share is not None:
        left += f", {100 * share:.0f}% of the geometric model's held-out MSE"
    top = [c for c in block["covariates"] if c["strength"] >= STRONG]
    if block.get("per_pose_dominates"):
        return f"Unexplained: {left}; mostly a per-pose error shared by all SMRs of a pose."
    if top:
        return f"Unexplained: {left}; it follows {top[0]['name']} most ({top[0]['strength']:.2f})."
    return f"Unexplained: {left}; no tested covariate explains it."
