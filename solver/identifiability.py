"""Which parameters the data can identify: redundancy with the base, the SMRs or each other."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .finite import finite
from .kinematics import Layout, predict_rows, predict_with_jacobian
from .observability import BLOCK_ROWS, stacked_r
from .plausibility import nominal_error_bound
from .prior import data_share

# Singular values of the unit-norm Jacobian columns below this fraction of the largest count as
# zero: exact redundancies sit near 1e-14, weak but real ones far above.
STRUCTURAL_TOL = 1e-8
# A column whose norm is below this fraction of the largest one's has no effect at all: lengths
# move the SMRs ~1 mm/mm and angles ~1000 mm/rad, rounding leaves ~1e-13 mm/rad.
DEAD = 1e-10
# A column adding less than this fraction of its norm is kept only if the rank needs it.
CLEAR_NEW = 0.1
# The error a parameter may plausibly have: the data must pin a parameter better than this
# (at the tracker's noise) for it to be identified. A geometric parameter pinned worse is
# shrunk toward nominal by a Gaussian prior of this standard deviation (solver.prior); a base
# or SMR entry, which has no prior, is held at nominal.
PRIOR_MM = 1.0
PRIOR_DEG = 1.0
# A geometric parameter the data pins, alone, to less than this share of the prior's
# information (a standard error ten times the prior's) does not move the SMRs: it is held. One
# the data moves but only together with others is shrunk, never held: holding it would hand
# its share of their common motion to the others as a precision they do not have (a UR5 whose
# one SMR is 0.1 mm off the flange axis, tracker noise x10, 80 poses, 30 seeds, true changes
# drawn from the prior: the identified parameters' 95% intervals covered 88% of the truths
# with a5 and alpha5 held, 94% with them shrunk; held-out error alike, 0.1662 mm).
HELD_INFO = 1e-2
# A geometric parameter less than this share of whose estimate comes from the data (1 -
# posterior / prior variance; information 1, the prior's, alone) is reported shrunk, and left
# out of the condition number: the data does not pin it better than the prior.
SHRUNK_SHARE = 0.5
# A fit whose free geometric parameters all take at least this share from the data moves by
# under 1% of each change with the prior's weight: not refitted when only the weight changes.
PRIOR_NEGLIGIBLE = 0.99
# The tracker noise (3-D RMS per reading) when the caller knows none: the default tracker spec,
# MPE 10 um + 2.5 um/m halved per axis, at 2 m.
DEFAULT_NOISE_FLOOR_MM = float(np.sqrt(3.0) * 0.5e-3 * (10.0 + 2.5 * 2.0))
STRUCTURAL_POSES = 240


class NotIdentifiable(ValueError):
    """The data cannot identify the model; the message names what cannot be identified."""


@dataclass
class Identifiability:
    """Parameters held fixed (with the reason) and the conditioning of the rest."""

    free: np.ndarray  # bool (P,)
    fixed: dict[str, str]  # name -> why it is held
    condition: float


def preference_order(layout: Layout) -> list[int]:
    """Columns in the order they should be kept: base, SMRs, then the joints.

    Keeping the base and SMR positions first hands the redundancy to joint 1 (theta, d) and the
    last joint, as calibration engineers expect; a parallel joint's d goes last because Hayati's
    beta replaces it.
    """
    names = layout.names()
    geo = list(range(layout.n_geo))
    late = [
        i for i in geo if names[i].startswith("d") and layout.robot.parallel[int(names[i][1:]) - 1]
    ]
    early = [i for i in geo if i not in late]
    base = list(range(layout.base_slice.start, layout.base_slice.stop))
    tgt = list(range(layout.target_slice.start, layout.target_slice.stop))
    return base + tgt + early + late


def _residual_norms(R: np.ndarray, basis: np.ndarray, cols) -> np.ndarray:
    """Part of each column outside span(basis), relative to the column's norm."""
    A = R[:, cols]
    norms = np.linalg.norm(A, axis=0)
    for _ in range(2):  # twice keeps Gram-Schmidt orthogonal
        A = A - basis @ (basis.T @ A)
    return np.linalg.norm(A, axis=0) / np.where(norms > 0, norms, 1.0)


def choose_free(R: np.ndarray, order, candidates: np.ndarray, tol: float) -> np.ndarray:
    """The parameters to identify: as many as the rank, well-conditioned, in preference order.

    The rank comes from the singular values of the unit-norm columns. A first sweep in
    preference order keeps columns that add a clearly new direction; then the columns adding
    the most are taken until the rank is reached. A plain greedy sweep with a tiny threshold
    would keep barely independent columns early (e.g. SMR coordinates that differ only through
    a slightly non-planar SMR triangle) and hold well-determined ones later.
    """
    cols = [j for j in order if candidates[j]]
    A = R[:, cols]
    norms = np.linalg.norm(A, axis=0)
    # a column this small against the largest is rounding, not an effect (an SMR on the axis)
    live = [c for c, n in zip(cols, norms) if n > DEAD * norms.max()]
    if not live:
        return np.zeros(R.shape[1], dtype=bool)
    s = np.linalg.svd(
        finite(R[:, live] / np.linalg.norm(R[:, live], axis=0), "the identification Jacobian"),
        compute_uv=False,
    )
    rank = int(np.sum(s > tol * s[0]))
    kept = np.zeros(R.shape[1], dtype=bool)
    basis = np.zeros((R.shape[0], 0))

    def add(j):
        v = R[:, j] - basis @ (basis.T @ R[:, j])
        v = v - basis @ (basis.T @ v)
        kept[j] = True
        return np.column_stack([basis, v / np.linalg.norm(v)])

    for j in live:
        if len(np.flatnonzero(kept)) < rank and _residual_norms(R, basis, [j])[0] > CLEAR_NEW:
            basis = add(j)
    while kept.sum() < rank:
        rest = [j for j in live if not kept[j]]
        basis = add(rest[int(np.argmax(_residual_norms(R, basis, rest)))])
    return kept


def _explain(R: np.ndarray, j: int, kept: np.ndarray, names) -> str:
    """Name the kept parameters that the redundant column j is mostly made of."""
    if np.linalg.norm(R[:, j]) <= DEAD * np.max(np.linalg.norm(R, axis=0)):
        return "no effect on the measured SMRs"
    idx = np.flatnonzero(kept)
    A = R[:, idx] / np.linalg.norm(R[:, idx], axis=0)
    coef, *_ = np.linalg.lstsq(
        finite(A, "the identification Jacobian"),
        finite(R[:, j] / np.linalg.norm(R[:, j]), "a parameter's column"),
        rcond=None,
    )
    share = np.abs(coef)
    # Equal shares (SMRs placed symmetrically) name the columns in order, whatever the rounding.
    top = np.lexsort((idx, -np.round(share / max(share.max(), 1e-300), 6)))[:3]
    labels = [names[idx[i]] for i in top if share[i] > 0.05]
    return "redundant with " + ", ".join(labels) if labels else "no effect on the measured SMRs"


def jacobian_rows(layout: Layout, x, q, mask) -> np.ndarray:
    """Identification Jacobian rows (readings x 3, P) of the measured readings."""
    _, Jt = predict_rows(layout, x, q, mask, np.arange(layout.n_params))
    return Jt.reshape(layout.n_params, -1).T


def structural(
    layout: Layout, x, candidates: np.ndarray, rows=None, pose_weight=None
) -> Identifiability:
    """Redundancies of the model itself, found on a rich set of random poses within the limits.

    Rows are the coordinates of the SMRs in `rows` (default all) or, with pose_weight, the
    ls-pose residuals. Depends only on the robot, the SMR layout and the method, so it is cached.
    """
    robot, names, targets, rows, weight = _key(layout, x, rows, pose_weight)
    free = np.asarray(candidates, dtype=bool).tobytes()
    return _structural(robot, names, targets, free, rows, weight)


@lru_cache(maxsize=64)
def _rich_r(robot, names, targets, rows, weight) -> np.ndarray:
    """structural_r on STRUCTURAL_POSES random poses within the limits (read-only)."""
    layout = Layout(robot, np.eye(4), names)
    x = layout.initial(np.reshape(targets, (-1, 3)))
    rng = np.random.default_rng(0)
    q = rng.uniform(robot.lower, robot.upper, size=(STRUCTURAL_POSES, robot.n_joints))
    R = structural_r(layout, x, q, rows, weight)
    R.setflags(write=False)
    return R


def _key(layout: Layout, x, rows, pose_weight):
    """The cache key of a layout's rich-pose R: robot, SMR names and positions, rows, weight."""
    K = len(layout.target_names)
    rows = tuple(range(K)) if rows is None else tuple(rows)
    targets = tuple(np.round(layout.targets(x), 3).ravel())
    weight = None if pose_weight is None else round(float(pose_weight), 6)
    return layout.robot, layout.target_names, targets, rows, weight


def layout_condition(layout: Layout, x, identified: np.ndarray, rows=None, pose_weight=None):
    """The condition number of the identified parameters on STRUCTURAL_POSES random poses within
    the limits: the least the robot and its SMR layout allow them, whatever the poses measured
    (an SMR 1 mm off the flange axis barely separates theta5 from a6 on any poses)."""
    R = _rich_r(*_key(layout, x, rows, pose_weight))
    return condition_number(R[:, np.asarray(identified, dtype=bool)])


@lru_cache(maxsize=64)
def _structural(robot, names, targets, candidates, rows, weight) -> Identifiability:
    layout = Layout(robot, np.eye(4), names)
    candidates = np.frombuffer(candidates, dtype=bool)
    R = _rich_r(robot, names, targets, rows, weight)
    kept = choose_free(R, preference_order(layout), candidates, STRUCTURAL_TOL)
    names_ = layout.names()
    fixed = {
        names_[j]: _explain(R, int(j), kept, names_) for j in np.flatnonzero(candidates & ~kept)
    }
    kept.setflags(write=False)
    # J = QR with Q orthonormal: R's columns have J's norms and its singular values
    return Identifiability(kept, fixed, condition_number(R[:, kept]))


def structural_r(layout: Layout, x, q, rows, weight) -> np.ndarray:
    """The R of a QR of the identification Jacobian at poses q, built a block of poses at a time.

    The whole Jacobian has (poses x SMRs x 3) rows of (3 x SMRs + geometry) columns, quadratic
    in the SMRs; a block of about BLOCK_ROWS rows stacked under the R so far keeps the memory
    linear in them (R'R is J'J, so everything taken from R is as from J itself).
    """
    from .identify import pose_residuals

    per_pose = 3 * len(rows) if weight is None else 6
    step = max(1, BLOCK_ROWS // per_pose)

    def blocks():
        for start in range(0, len(q), step):
            p, J, _ = predict_with_jacobian(layout, x, q[start : start + step])
            if weight is None:
                yield J[:, list(rows)].reshape(-1, layout.n_params)
            else:
                yield pose_residuals(p, p, J, weight)[1].reshape(-1, layout.n_params)

    return stacked_r(blocks(), layout.n_params)


def condition_number(J: np.ndarray) -> float:
    """Condition number of J after scaling every column to unit norm; NaN without a column
    (nothing identified: every parameter the data moves shrunk toward nominal)."""
    if J.shape[-1] == 0:
        return float("nan")
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    s = np.linalg.svd(finite(J / norms, "the identification Jacobian"), compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


@dataclass(frozen=True)
class Shrunk:
    """A parameter the data sees too little to identify, fitted with the prior: the share of
    its estimate that comes from the data (1 - posterior / prior variance) and why."""

    share: float
    why: str


@dataclass
class DataCheck:
    """What the data itself identifies: the free parameters left (identified or shrunk), those
    it holds and why, those it sees too little to identify (shrunk toward nominal) and why, and
    the condition number of the identified ones."""

    free: np.ndarray  # bool (P,)
    held: dict[str, str]  # name -> why the data cannot identify it
    condition: float
    shrunk: dict[str, Shrunk] = field(default_factory=dict)  # name -> its data share and why
    least_share: float = 1.0  # the least share of a free geometric parameter's from the data
    # bool (P,): the identified, those the condition number is of
    identified: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


def check_data(
    A: np.ndarray, free: np.ndarray, layout: Layout, n_rows: int, n_poses: int, noise_mm=None
) -> DataCheck:
    """Sort the free parameters into identified, shrunk and held; refuse only too few equations.

    A is J'J over the free parameters (n_rows rows of J), noise_mm the residual's RMS a reading.
    Held at nominal, with the reason: a geometric parameter the data pins, alone, to less than
    HELD_INFO of the prior's information (a column the data does not move: one SMR on the last
    joint's axis and its offset), and a base or SMR entry (which has no prior) the data pins,
    given those it pins better before it (preference order), worse than PRIOR_MM or PRIOR_DEG.
    The geometric rest is fitted with the prior (solver.prior); those whose estimate would be
    less than SHRUNK_SHARE the data's (the posterior at this noise) are shrunk toward nominal,
    with the share and the reason. The condition number is that of the unit-column Jacobian of
    the identified ones: those the data pins better than the prior given the ones before them
    (so the data alone identifies them together), shrunk ones left out.
    """
    names = layout.names()
    idx = np.flatnonzero(free)
    if n_rows < len(idx):
        raise NotIdentifiable(
            f"{n_poses} poses give {n_rows} equations for {len(idx)} parameters: "
            f"measure at least {int(np.ceil(len(idx) / max(1, n_rows // max(n_poses, 1))))} poses"
        )
    sigma = (DEFAULT_NOISE_FLOOR_MM if not noise_mm else float(noise_mm)) / np.sqrt(3.0)
    angle = np.zeros(layout.n_params, dtype=bool)
    angle[[op.param for op in layout.ops() if op.kind == "r"]] = True
    prior = np.where(angle[idx], np.deg2rad(PRIOR_DEG), PRIOR_MM)
    # information in units of the prior: a direction below 1 is known no better than the prior
    B = finite(A, "the normal matrix") * np.outer(prior, prior) / sigma**2
    geo = idx < layout.n_geo
    at = {int(p): i for i, p in enumerate(idx)}
    kept: list[int] = []
    held: dict[str, str] = {}
    weak: list[int] = []
    for p in (p for p in preference_order(layout) if p in at):
        i = at[p]
        info = _added(B, i, kept)
        if info >= 1.0:
            kept.append(i)
        elif geo[i] and B[i, i] >= HELD_INFO:
            weak.append(i)
        else:
            held[names[p]] = _why_held(B, i, info, kept, idx, names, angle[p], sigma * np.sqrt(3.0))
    if not kept:
        bound = nominal_error_bound(layout.robot)
        if noise_mm and noise_mm > bound:  # a fit's residual: the description, not the poses
            raise NotIdentifiable(
                f"the fit stays {noise_mm:.4g} mm RMS from the readings (more than the "
                f"{bound:.3g} mm any calibration of a right description of this arm leaves): the "
                "cell's robot is not the arm measured (a twist's or a joint's sign, a joint "
                "offset convention, a link's length, another robot)"
            )
        raise NotIdentifiable(
            "the data moves none of the parameters: measure poses that move the SMRs"
        )
    on = np.array(sorted(kept + weak), dtype=int)
    # the posterior in prior units: (B + I on the geometry)^-1; its diagonal, the prior's share
    share = data_share(B[np.ix_(on, on)], geo[on].astype(float))
    low = on[geo[on] & (share < SHRUNK_SHARE)]
    # the identified: those kept (the data pins each given the ones before it) not shrunk; a
    # weak one mostly from the data is neither (the prior resolves what it shares with others)
    ident = sorted(set(kept) - set(low.tolist()))
    shrunk = {
        names[idx[i]]: Shrunk(
            float(share[list(on).index(i)]),
            _why_held(
                B, i, _added(B, i, ident), ident, idx, names, angle[idx[i]], sigma * np.sqrt(3.0)
            ),
        )
        for i in sorted(low.tolist(), key=lambda i: idx[i])
    }
    keep = np.zeros_like(np.asarray(free, dtype=bool))
    keep[idx[on]] = True
    sub = np.array(ident, dtype=int)
    Ak = A[np.ix_(sub, sub)]
    norms = np.sqrt(np.diag(Ak))
    As = Ak / np.outer(norms, norms)
    s = np.sqrt(np.clip(np.linalg.eigvalsh(finite(As, "the normal matrix"))[::-1], 0.0, None))
    cond = float(s[0] / s[-1]) if len(s) and s[-1] > 0 else float("inf")
    least = float(share[geo[on]].min()) if geo[on].any() else 1.0
    identified = np.zeros_like(keep)
    identified[idx[sub]] = True
    return DataCheck(keep, held, cond, shrunk, least, identified)


def _added(B: np.ndarray, i: int, kept: list[int]) -> float:
    """The information (prior units) column i of B adds to the columns kept."""
    if not kept:
        return float(B[i, i])
    L = np.linalg.cholesky(B[np.ix_(kept, kept)])
    v = np.linalg.solve(L, B[kept, i])
    return float(B[i, i] - v @ v)


def _why_held(B, i, info, kept, idx, names, is_angle, floor) -> str:
    """Why column i of the information matrix B (prior units) is held: unmoved, below the noise,
    or moved only with the kept parameters (info: what it adds to them)."""
    unit, scale = ("deg", PRIOR_DEG) if is_angle else ("mm", PRIOR_MM)
    if B[i, i] <= 0.0:
        return "no effect on the measured SMRs in this data"
    alone = scale / np.sqrt(B[i, i])
    if B[i, i] < 1.0:
        return (
            f"moves the measured SMRs below the noise (standard error "
            f"{alone:.3g} {unit} alone, at {floor:.4f} mm noise)"
        )
    d = np.sqrt(np.diag(B))
    Bn = B[np.ix_(kept, kept)] / np.outer(d[kept], d[kept])
    coef = np.linalg.lstsq(Bn, B[kept, i] / d[kept] / d[i], rcond=None)[0]
    top = [names[idx[kept[k]]] for k in np.argsort(-np.abs(coef))[:3] if abs(coef[k]) > 0.05]
    return (
        "the data moves it only together with "
        + (", ".join(top) if top else "the other parameters")
        + f" (standard error {alone:.3g} {unit} alone, {scale / np.sqrt(max(info, 1e-300)):.3g} {unit}"
        " with them)"
    )


def gram(J: np.ndarray, free: np.ndarray) -> np.ndarray:
    """J'J over the free columns of J (rows, P)."""
    Jf = J[:, np.flatnonzero(free)]
    return Jf.T @ Jf


def effective_parameters(column: np.ndarray, shrunk: dict[str, Shrunk] | None) -> int:
    """How many parameters a fit spends of its equations: those it fits (column >= 0), a shrunk
    one counting as the share of it the data gives (a prior-fitted model's residuals keep the
    equations less the trace of its hat matrix)."""
    spent = np.count_nonzero(np.asarray(column) >= 0)
    return int(round(spent - sum(1.0 - s.share for s in (shrunk or {}).values())))
