"""A verification's uncertainty and its decisions: U of the model at each test point, the AP
figures' own U from the tracker's specification, the RP figures' from their visits and the
tracker's (solver.repeatability), and pass / fail / not decided against the application's
tolerance (AP) and the arm's stated repeatability (RP) by the guard-banded rule of ISO 14253-1."""

from __future__ import annotations

import numpy as np

from robocal.server.calibration.position_uncertainty import missing_inputs, model_uncertainty
from robocal.server.formats.cell_json import Cell
from robocal.server.formats.model_json import ModelFile

RULE = (
    "ISO 14253-1 guard bands: pass only when every point's AP plus its U is within the "
    "tolerance, fail when any point's AP minus its U is beyond it, otherwise not decided"
)
RP_RULE = (
    "ISO 14253-1 guard bands: pass only when every point's RP plus its U above is within the "
    "arm's stated repeatability, fail when any point's RP minus its U below is beyond it, "
    "otherwise not decided"
)
RP_U = (
    "U of an RP (95 %): below and above the figure, from the spread of the visits (a parametric "
    "bootstrap of their 3-D scatter: few visits show RP low, so U above is the larger) and, "
    "below only, the most the tracker's random error (its spec's sigma, MPE / 2) can have "
    "widened the spread"
)
AP_U = (
    "U of an AP: the tracker's MPE at the point's range (its spec's per-axis sigma = MPE / 2 "
    "along the error, k = 2), not averaged over the cycles"
)


def mpe_mm(cell: Cell, points_mm) -> np.ndarray:
    """The tracker's maximum permissible error (mm) at each point's range from the tracker."""
    spec = cell.tracker or {}
    r_m = np.linalg.norm(np.asarray(points_mm, dtype=float), axis=-1) / 1000.0
    return 1e-3 * (float(spec.get("mpe_um", 10.0)) + float(spec.get("mpe_um_per_m", 2.5)) * r_m)


def at_points(model: ModelFile, cell: Cell, q_deg, points_mm) -> dict | None:
    """The model's U (95 %) at each test point, the arm's position itself and as a reading
    would find it, from the compensated joints that visit it (q_deg (p, n)); None for a model
    without a position block."""
    reading = np.sqrt(3.0) * mpe_mm(cell, points_mm) / 2.0  # 3-D RMS: per-axis sigma MPE / 2
    q = np.radians(np.asarray(q_deg, dtype=float))
    own = model_uncertainty(model, q)
    read = model_uncertainty(model, q, reading[:, None])
    if own is None or read is None:
        return None
    return {
        "coverage": own.coverage,
        "map": volume_map(model),
        "model_U_mm": own.expanded_mm[:, 0].tolist(),
        "reading_U_mm": read.expanded_mm[:, 0].tolist(),
        "k": own.k[:, 0].tolist(),
        "joint_scatter_deg": own.joint_scatter_deg,
    }


AT_VISITS = (
    "Model U at each visit's time and temperature, which its time or temperature terms "
    "({terms}) need (the largest over the point's visits); {joints}, and the volume's map is "
    "not drawn"
)
# how the compensated joints took the model's time or temperature terms
PLANNED = (
    "the joints were compensated without those terms, which a plan made before the run cannot know"
)
PER_VISIT = (
    "the joints were compensated at the air temperature the tracker read as each pose was due"
)
PER_VISIT_UNTIMED = (
    PER_VISIT
    + " and without its time terms ({untimed}), which a plan made before the run cannot know"
)
UNTEMPERED = (
    "{n} of the compensated run's {total} poses were compensated without the model's "
    "temperature terms ({terms}): the cell had reported no temperature before them."
)
STALE = (
    "{n} of the compensated run's {total} poses were compensated at the air temperature of an "
    "earlier reading, the tracker's weather station giving none as they were due: up to "
    "{minutes:.1f} min old."
)
NOT_GIVEN = (
    "Model U is not given: the model's time or temperature terms ({terms}) need each visit's "
    "time or temperature, which this run's readings do not carry."
)


def timed_terms(model: ModelFile) -> list[str]:
    """The model's extensions whose prediction needs a pose's time or temperature."""
    return missing_inputs(model)


def terms_on(model: ModelFile, column: str) -> list[str]:
    """The model's extensions that need this pose column (time_s, temp_c), as timed_terms."""
    return [t for t in timed_terms(model) if t.endswith(f" on {column}")]


def joints_clause(model: ModelFile, per_visit: bool) -> str:
    """How the compensated joints took the model's time or temperature terms: left out of a
    plan made before the run, or (per_visit) its temperature terms at each pose's."""
    if not per_visit:
        return PLANNED
    untimed = terms_on(model, "time_s")
    return PER_VISIT_UNTIMED.format(untimed=", ".join(untimed)) if untimed else PER_VISIT


def untempered(model: ModelFile, temps) -> str | None:
    """The sentence saying how many of the compensated poses (each one's temperature, None when
    the cell had reported none) were compensated without the temperature terms; None if none."""
    n = sum(1 for t in temps if t is None)
    if not n:
        return None
    terms = ", ".join(terms_on(model, "temp_c"))
    return UNTEMPERED.format(n=n, total=len(temps), terms=terms)


def stale(ages_s) -> str | None:
    """The sentence saying how many of the compensated poses (each one's temperature's age, s:
    0 read as the pose was due, None not kept or none) were compensated at an earlier reading's
    temperature, and how old the oldest was; None if none."""
    old = [a for a in ages_s if a]
    if not old:
        return None
    return STALE.format(n=len(old), total=len(ages_s), minutes=max(old) / 60.0)


def at_visits(
    model: ModelFile, cell: Cell, q_rad, time_s, temp_c, point, points_mm, joints: str = PLANNED
) -> dict:
    """The model's U (95 %) at each test point from its visits (q_rad (v, n), each visit's
    time_s and temp_c (v,) or None, point (v,) its test point): at each visit's time and
    temperature, the largest over the point's visits; `model` None and `model_note` the reason
    where a visit lacks what the model's extensions need. `joints` (joints_clause) says how the
    compensated joints took those terms."""
    q = np.asarray(q_rad, dtype=float)
    K = len(model.targets)
    wide = lambda a: None if a is None else np.repeat(np.asarray(a, float)[:, None], K, 1)  # noqa: E731
    t, c = wide(time_s), wide(temp_c)
    point = np.asarray(point)
    reading = np.sqrt(3.0) * mpe_mm(cell, np.asarray(points_mm)[point]) / 2.0
    own = model_uncertainty(model, q, 0.0, t, c)
    read = model_uncertainty(model, q, reading[:, None], t, c)
    terms = ", ".join(timed_terms(model))
    if (own is None or read is None) and not missing_inputs(model, t, c):
        return {"model": None}  # a model without a position block: the certificate says so
    if own is None or read is None:
        return {"model": None, "model_note": NOT_GIVEN.format(terms=terms)}
    worst = lambda a: [float(a[point == j, 0].max()) for j in range(len(points_mm))]  # noqa: E731
    return {
        "model": {
            "coverage": own.coverage,
            "map": None,
            "model_U_mm": worst(own.expanded_mm),
            "reading_U_mm": worst(read.expanded_mm),
            "k": worst(own.k),
            "joint_scatter_deg": own.joint_scatter_deg,
        },
        "model_note": AT_VISITS.format(terms=terms, joints=joints),
    }


def decision(
    figure_mm,
    u_mm,
    tolerance_mm: float | None,
    tracker_overdue: str | None = None,
    below=None,
    rule: str = RULE,
) -> dict:
    """The verdict on figures (mm: the APs, or the RPs) with their U against the tolerance:
    `pass`, `fail` or `not decided` (and `no tolerance` without one), with the rule and the
    figures it used; `below`, where U differs below the figure, is that U (default u_mm). A
    tracker past its calibration's due date never passes: its U is not vouched for."""
    ap, u = np.asarray(figure_mm, dtype=float), np.asarray(u_mm, dtype=float)
    lower = ap - (u if below is None else np.asarray(below, dtype=float))
    if tolerance_mm is None:
        verdict = "no tolerance"
    elif np.all(ap + u <= tolerance_mm):
        verdict = "not decided" if tracker_overdue else "pass"
    elif np.any(lower > tolerance_mm):
        verdict = "fail"
    else:
        verdict = "not decided"
    return {
        "verdict": verdict,
        "tracker_overdue": tracker_overdue,
        "tolerance_mm": tolerance_mm,
        "rule": rule,
        "worst_upper_mm": float(np.max(ap + u)),
        "worst_lower_mm": float(np.max(lower)),
    }


MAP_POSES = 600


def volume_map(model: ModelFile, poses: int = MAP_POSES, seed: int = 0) -> dict | None:
    """U (95 %, the position itself) of the verification SMR over the working volume: at joints
    drawn uniformly within the arm's limits (seeded: the same map for the same model)."""
    from robocal.solver.kinematics import predict

    rng = np.random.default_rng(seed)
    lo, hi = (np.array([j.limits[i] for j in model.robot.joints]) for i in (0, 1))
    q = rng.uniform(lo, hi, size=(poses, len(lo)))
    u = model_uncertainty(model, q)
    if u is None:
        return None
    lay, x = model.layout()
    xyz = predict(lay, x, q)[:, 0]
    return {"xyz_mm": np.round(xyz, 1).tolist(), "U_mm": np.round(u.expanded_mm[:, 0], 5).tolist()}
