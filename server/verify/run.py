"""`robocal acquire --verify model.json`: an ISO 9283 verification run of a calibrated model.

Each test point (the standard cube's five, or a points.csv) is visited from several approach
directions, several cycles, once with the joints the nominal arm gives and once with the model's
compensated joints; both runs go through `acquire` (the cell's devices, the campaign engine, the
store), and the tracker's readings of one SMR give the ISO figures before and after.
"""

from __future__ import annotations

import csv
import datetime as dt
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.server import store
from robocal.server.acquisition.acquire import PREDICTOR, AcquireOptions, acquire
from robocal.server.acquisition.compensated import (
    AGES,
    KEY,
    TEMPS,
    plan_block,
    temperature_terms,
    total_poses,
    without,
)
from robocal.server.calibration.validation import cell_mismatch
from robocal.server.compensate.compensation import MAX_ERROR_MM, solver_model
from robocal.server.formats.blocks import ModelQuote
from robocal.server.formats.cell_json import Cell, parse_cell, robot_to_json
from robocal.server.formats.errors import InputError
from robocal.server.formats.model_json import ModelFile, parse_model, read_model
from robocal.server.formats.verification_doc import RunFigures, VerificationDoc
from robocal.server.verify.uncertainty import (
    AP_U,
    RP_RULE,
    RP_U,
    at_points,
    at_visits,
    decision,
    joints_clause,
    mpe_mm,
    stale,
    timed_terms,
    untempered,
)
from robocal.solver.compensate import compensate
from robocal.solver.iso9283 import (
    CUBE_PAIRS,
    cube_points,
    distance_figures,
    multidirectional_variation,
    position_figures,
)
from robocal.solver.measurements import Measurements

APPROACH_MM = 50.0  # each approach pose stands this far from its point
# approach directions, in the order they are taken: from above, then along the cell's axes
DIRECTIONS = np.array(
    [[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float
)
CUBE_SIDE_MM = 400.0
REFERENCE_CANDIDATES = 60  # visible poses drawn to place the cube near the workspace's middle
RUNS = ("nominal", "compensated")  # the campaign visits the plan with each joint set, in turn
RECORD = "verification"  # the campaign settings' key of the plan the figures come from
# what a verification record quotes of its model's verdict (formats.blocks.ModelQuote)
QUOTED = {"deployable", "holdout_rms_mm", "tolerance_mm"}


@dataclass
class VerifyOptions:
    """How to verify: points (None: the ISO cube), cycles, approach directions, the cube."""

    cycles: int = 3
    directions: int = 3
    points_path: str | None = None
    points: tuple | None = None  # (names, (p, 3) mm) given inline, as the API takes them
    side_mm: float = CUBE_SIDE_MM
    seed: int = 0
    name: str = "verify"
    effects: tuple = ()
    pause_s: float = 10.0
    samples: int = 1000  # tracker samples a reading, as the calibration campaign took them
    settle: str = "fixed"
    arm: str | None = None  # the physical arm measured (its serial number)


def read_points(path) -> tuple[list[str], np.ndarray]:
    """points.csv: `point,x_mm,y_mm,z_mm` per line (cell frame, mm): (names, (p, 3))."""
    names, xyz = [], []
    with open(path, newline="") as f:
        rows = csv.reader(f)
        header = next(rows, None)
        want = ["point", "x_mm", "y_mm", "z_mm"]
        if header is None or [h.strip() for h in header] != want:
            raise InputError(path, 1, None, f"the header must be {','.join(want)}")
        for line, row in enumerate(rows, start=2):
            if not row or not "".join(row).strip():
                continue
            if len(row) != 4:
                raise InputError(path, line, None, "needs 4 fields: point,x_mm,y_mm,z_mm")
            for col, (field, v) in enumerate(zip(want[1:], row[1:]), start=2):
                try:
                    val = float(v)
                except ValueError:
                    val = float("nan")
                if not np.isfinite(val):
                    raise InputError(path, line, col, f"{field}: {v!r} is not a finite number")
            names.append(row[0].strip())
            xyz.append([float(v) for v in row[1:]])
    if len(names) < 1:
        raise InputError(path, 1, None, "no points")
    return names, np.array(xyz)


def nominal_file(model: ModelFile) -> ModelFile:
    """What an uncalibrated cell commands with: the nominal arm on the model's base and SMRs."""
    return ModelFile(model.nominal or model.robot, model.base, dict(model.targets))


def reference_poses(model: ModelFile, seed: int) -> np.ndarray:
    """Poses (c, n) rad the tracker sees, their first SMR nearest the middle of the visible
    workspace first: candidates for the cube's centre and the test points' orientation."""
    from robocal.drivers.planning import plan_poses

    offsets = np.array(list(model.targets.values()))
    q = plan_poses(
        model.nominal or model.robot,
        model.base,
        offsets,
        REFERENCE_CANDIDATES,
        np.random.default_rng([seed, 9283]),
    )
    p = solver_model(nominal_file(model)).evaluate(q)[0][:, 0]
    return q[np.argsort(np.linalg.norm(p - np.median(p, axis=0), axis=1))]


@dataclass
class Plan:
    """The run's poses: desired SMR positions (m, K, 3), which are measured test visits, and for
    each of those its point, cycle and approach direction."""

    desired: np.ndarray
    visit: np.ndarray  # (m,) bool: a test point (else an approach pose)
    point: np.ndarray  # (m,) index of the test point visited or approached
    cycle: np.ndarray
    direction: np.ndarray
    points: np.ndarray  # (p, 3) commanded positions of the verification SMR
    names: list[str]
    q_ref: np.ndarray | None


def make_plan(model: ModelFile, opts: VerifyOptions) -> tuple[Plan, dict]:
    """The plan about the first reference pose from which both the nominal arm and the model
    reach every pose, and its joint commands {"nominal": (m, n) deg, "compensated": ...}."""
    error = None
    for q_ref in reference_poses(model, opts.seed):
        plan = plan_about(model, opts, q_ref)
        if error is None:
            check_within_reach(model, plan)  # else every reference pose would be tried in vain
        try:
            return plan, {w: joints_for(model, plan, w) for w in ("nominal", "compensated")}
        except ValueError as e:
            error = e
    raise ValueError(f"no reference pose reaches every test point: {error}")


# Beyond the links' bound: extensions (compliance, a gear's error) move the SMR well under this.
REACH_MARGIN_MM = 10.0


def check_within_reach(model: ModelFile, plan: Plan) -> None:
    """ValueError at once for a test point farther from the arm's base than any pose can put the
    verification SMR (its links plus its offset from the flange), naming the point."""
    offset = float(np.linalg.norm(next(iter(model.targets.values()))))
    robots = [model.robot] + ([model.nominal] if model.nominal is not None else [])
    reach = max(r.reach_mm for r in robots) + offset + REACH_MARGIN_MM
    far = np.linalg.norm(plan.points - np.asarray(model.base)[:3, 3], axis=1)
    for j in np.flatnonzero(far > reach):
        raise ValueError(
            f"test point {plan.names[j]} is unreachable: {far[j]:.0f} mm from the arm's base, "
            f"beyond its reach of {reach:.0f} mm (links plus the SMR's offset)"
        )


def plan_about(model: ModelFile, opts: VerifyOptions, q_ref) -> Plan:
    """Cycles x directions x points, each point preceded by its approach pose; every pose keeps
    the reference pose's orientation (the SMRs translated rigidly)."""
    smrs = solver_model(model).evaluate(q_ref[None])[0][0]  # (K, 3) as the model has them
    if opts.points_path:
        names, points = read_points(opts.points_path)
    elif opts.points is not None:
        names, points = list(opts.points[0]), np.asarray(opts.points[1], dtype=float)
    else:
        names, points = [f"P{i}" for i in range(1, 6)], cube_points(smrs[0], opts.side_mm)
    dirs = DIRECTIONS[: opts.directions]
    desired, visit, point, cycle, direction = [], [], [], [], []
    for c in range(opts.cycles):
        for d, u in enumerate(dirs):
            for j, p in enumerate(points):
                shift = p - smrs[0]
                for is_visit, extra in ((False, APPROACH_MM * u), (True, 0.0)):
                    desired.append(smrs + shift + extra)
                    visit.append(is_visit)
                    point.append(j)
                    cycle.append(c)
                    direction.append(d)
    return Plan(
        np.array(desired),
        np.array(visit),
        np.array(point),
        np.array(cycle),
        np.array(direction),
        points,
        names,
        q_ref,
    )


def joints_for(model: ModelFile, plan: Plan, what: str) -> np.ndarray:
    """The plan's joint commands (m, n) deg from the nominal arm or the calibrated model."""
    sm = solver_model(nominal_file(model) if what == "nominal" else model)
    mask = np.ones(plan.desired.shape[:2], dtype=bool)
    assert plan.q_ref is not None, "a stored plan's layout has no reference pose to solve from"
    q0 = np.repeat(plan.q_ref[None], len(plan.desired), axis=0)
    res = compensate(sm, plan.desired, mask, q0)
    bad = np.flatnonzero(~(res.error_mm <= MAX_ERROR_MM))
    if len(bad):
        k = int(bad[0])
        raise ValueError(
            f"verification pose {k + 1} (point {plan.names[plan.point[k]]}) is unreachable with "
            f"the {what} joints: {res.error_mm[k]:.3f} mm RMS off"
        )
    return np.rad2deg(res.q)


def figures(plan: Plan, attained: np.ndarray, tracker_sigma_mm=0.0) -> RunFigures:
    """The ISO figures (mm) of one run from the verification SMR's readings (m, 3), each RP
    with its U below and above (solver.repeatability; the tracker's per-axis random error
    tracker_sigma_mm at each point)."""
    from robocal.solver.repeatability import rp_uncertainty

    p, n = len(plan.points), int(plan.visit.sum()) // len(plan.points)
    a = np.full((p, n, 3), np.nan)
    dirs = np.zeros(n, dtype=int)
    for j in range(p):
        rows = np.flatnonzero(plan.visit & (plan.point == j))
        a[j] = attained[rows]
        dirs = plan.direction[rows]
    if not np.all(np.isfinite(a)):
        raise ValueError("a test point's reading is missing; run the verification again")
    pos = position_figures(a, plan.points)
    rp_u = rp_uncertainty(a, tracker_sigma_mm)
    out = {
        "points": [
            {
                "point": plan.names[j],
                "commanded_mm": plan.points[j].tolist(),
                "AP_mm": float(pos.ap[j]),
                "AP_xyz_mm": pos.ap_xyz[j].tolist(),
                "RP_mm": float(pos.rp[j]),
                "RP_U_below_mm": float(rp_u.below[j]),
                "RP_U_above_mm": float(rp_u.above[j]),
                "vAP_mm": float(multidirectional_variation(a[j : j + 1], dirs)[0]),
                "attained_mm": a[j].tolist(),
            }
            for j in range(p)
        ],
        "AP_max_mm": float(pos.ap.max()),
        "RP_max_mm": float(pos.rp.max()),
    }
    pairs = CUBE_PAIRS if p == 5 and plan.names == [f"P{i}" for i in range(1, 6)] else []
    if not pairs and p >= 2:
        pairs = [(0, j) for j in range(1, p)]
    if pairs:
        # the distance between two points is taken within each cycle and approach
        d = distance_figures(a, plan.points, pairs)
        out["distances"] = [
            {
                "pair": [plan.names[i], plan.names[j]],
                "AD_mm": float(d.ad[k]),
                "RD_mm": float(d.rd[k]),
            }
            for k, (i, j) in enumerate(pairs)
        ]
    return RunFigures.model_validate(out)


def _sha256(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def check_options(opts: VerifyOptions) -> None:
    """ValueError naming the option that cannot make a verification."""
    if opts.cycles < 1 or not 1 <= opts.directions <= len(DIRECTIONS):
        raise ValueError(f"--cycles must be >= 1 and --directions 1 to {len(DIRECTIONS)}")
    if opts.cycles * opts.directions < 2:
        raise ValueError(
            "repeatability needs at least two visits a point (--cycles x --directions)"
        )
    if not opts.side_mm > 0:
        raise ValueError("--side must be a positive length, mm")


def prepare(
    cell: Cell, model_path, opts: VerifyOptions, model_name: str | None = None, report=None
):
    """The run's joint commands (2m, n) deg, the nominal visits then the compensated ones, their
    pose labels, and the campaign's settings: the plan the figures are computed from, and the
    model's geometry, from which the tracker is aimed (clustered poses teach a predictor little).
    A model with a temperature term: the nominal visits' (m, n) only, the compensated ones to be
    solved during the run from the settings' compensated_plan (run_poses counts them all)."""
    check_options(opts)
    model = read_model(model_path)
    why = cell_mismatch(model, cell)
    if why:
        raise InputError(model_path, None, None, f"{why}: not a model of this cell")
    # a plan made before the run cannot know its visits' time and temperature: the terms that
    # need them are left out of the planned joints (the model kept whole for U at the visits'
    # inputs); a temperature term's compensated joints are solved as each pose is due, at the
    # air temperature the tracker reads then (acquisition/compensated.py)
    timed = timed_terms(model)
    text = Path(model_path).read_text(encoding="utf-8") if timed else None
    plan, joints = make_plan(untimed(model) if timed else model, opts)
    labels = pose_labels(plan)
    deferred = {}
    if temperature_terms(model):
        assert plan.q_ref is not None and text is not None  # a temperature term is timed
        m = len(plan.visit)
        deferred = {KEY: plan_block(text, plan.desired, plan.q_ref, labels[m:], after=m)}
    record = {
        "model": {
            "path": model_name or str(model_path),
            "sha256": _sha256(model_path),
            # what the certificate quotes of the model: its held-out RMS (a diagnosis's final
            # model's, else the calibration's leave-one-pose-out one from its validation)
            "meta": {
                "diagnosis": {"final": model.diagnosis.final.to_json() if model.diagnosis else {}},
                "validation": (
                    model.validation.model_dump(include=QUOTED, exclude_unset=True)
                    if model.validation
                    else {}
                ),
            },
        },
        "smr": list(model.targets)[0],
        # U of the model at each test point, from the compensated joints that visit it
        "uncertainty": at_points(
            model,
            cell,
            [joints["compensated"][_first_visit(plan, j)] for j in range(len(plan.names))],
            plan.points,
        ),
        # the model whose U needs each visit's time or temperature, as its file has it; kept
        # once: where the run compensates its temperature terms, in the plan block (KEY) alone
        **({"timed_model": text} if timed and not deferred else {}),
        "cycles": opts.cycles,
        "directions": opts.directions,
        "approach_mm": APPROACH_MM,
        "points": plan.names,
        "points_mm": plan.points.tolist(),
        "visit": plan.visit.tolist(),
        "point": plan.point.tolist(),
        "cycle": plan.cycle.tolist(),
        "direction": plan.direction.tolist(),
    }
    geometry = {
        "robot": robot_to_json(model.robot),
        "base": np.asarray(model.base).tolist(),
        "targets": {k: np.asarray(v).tolist() for k, v in model.targets.items()},
    }
    settings = {RECORD: record, PREDICTOR: geometry, **deferred}
    if deferred:  # the nominal run is planned; the compensated one is solved during the run
        return joints["nominal"], labels[: len(plan.visit)], settings
    return np.vstack([joints[w] for w in RUNS]), labels, settings


def run_poses(q_deg, settings: dict) -> int:
    """The run's poses: those prepare() planned, and those solved during the run."""
    return total_poses(settings, len(q_deg))


def untimed(model: ModelFile) -> ModelFile:
    """The model without the extensions that need a pose's time or temperature."""
    return without(model, {"time_s", "temp_c"})


def _first_visit(plan: Plan, j: int) -> int:
    """The plan's first measured visit of test point j."""
    return int(np.flatnonzero(plan.visit & (plan.point == j))[0])


def pose_labels(plan: Plan) -> list[str]:
    """The campaign's pose labels: the run, the point, the cycle and the direction of each."""
    return [
        f"{what}-p{j + 1}-c{c + 1}-d{d + 1}" + ("" if v else "-approach")
        for what in RUNS
        for j, c, d, v in zip(plan.point, plan.cycle, plan.direction, plan.visit)
    ]


def _layout(record: dict) -> Plan:
    """The plan's layout as stored with the campaign (no desired positions, no reference)."""
    return Plan(
        np.empty((0, 0, 3)),
        np.array(record["visit"], dtype=bool),
        np.array(record["point"], dtype=int),
        np.array(record["cycle"], dtype=int),
        np.array(record["direction"], dtype=int),
        np.array(record["points_mm"], dtype=float),
        list(record["points"]),
        None,
    )


def is_verification(info: store.CampaignInfo) -> bool:
    return RECORD in (info.settings or {})


def readings(db, campaign_id: int) -> tuple[store.CampaignInfo, Measurements]:
    """A done verification campaign and its readings of the verification SMR; NotFound if the
    campaign is no verification, Conflict until it is done."""
    info = store.get_campaign(db, campaign_id=campaign_id)
    if not is_verification(info):
        raise store.NotFound(f"campaign {campaign_id} is not a verification run")
    if info.status != "done":
        raise store.Conflict(
            f"campaign {campaign_id} is {info.status}; its figures come once it is done"
        )
    smr = info.settings[RECORD]["smr"]
    return info, store.campaign_measurements(db, campaign_id=campaign_id, targets=[smr])


def verification_report(
    info: store.CampaignInfo, meas: Measurements, report=None
) -> VerificationDoc:
    """The verification report of a done campaign from its readings (readings() gives both)."""
    record = info.settings[RECORD]
    plan = _layout(record)
    m = len(plan.visit)
    row_of = {label: k for k, label in enumerate(pose_labels(plan))}
    attained = np.full((2 * m, 3), np.nan)
    times, temps = np.full(2 * m, np.nan), np.full(2 * m, np.nan)
    joints = np.full((2 * m, meas.q.shape[1]), np.nan)
    for row, label in enumerate(meas.pose_ids):
        k = row_of.get(label)
        if k is not None:
            attained[k], joints[k] = meas.xyz[row, 0], meas.q[row]
            if meas.time_s is not None:
                times[k] = meas.time_s[row, 0]
            if meas.temp_c is not None:
                temps[k] = meas.temp_c[row, 0]
    cell = parse_cell(info.cell_json, f"<campaign {info.id} cell>")
    model_u: dict = {"model": record.get("uncertainty")}
    timed_text = timed_model_text(info.settings)
    if timed_text:
        visits = m + np.flatnonzero(plan.visit)  # the compensated run's test visits
        timed = parse_model(timed_text, f"<campaign {info.id} model>")
        per_visit = KEY in info.settings  # its temperature terms solved as each pose was due
        model_u = at_visits(
            timed,
            cell,
            joints[visits],
            times[visits] if meas.time_s is not None else None,
            temps[visits] if meas.temp_c is not None else None,
            plan.point[plan.visit],
            plan.points,
            joints_clause(timed, per_visit),
        )
        if per_visit:
            said = [
                untempered(timed, info.settings.get(TEMPS, ())),
                stale(info.settings.get(AGES, ())),
            ]
            if any(said):
                model_u["compensation_note"] = " ".join(filter(None, said))
    ap_u = mpe_mm(cell, plan.points)
    runs: dict[str, RunFigures] = {}
    seconds: dict[str, float | None] = {}
    for h, what in enumerate(RUNS):
        part = slice(h * m, (h + 1) * m)
        runs[what] = figures(plan, attained[part], ap_u / 2.0)  # the spec's sigma: MPE / 2
        t = times[part][np.isfinite(times[part])]
        seconds[what] = float(t.max() - t.min()) if len(t) else None
    after = runs["compensated"].points
    ap = [p.AP_mm for p in after]
    for p, u in zip(after, ap_u):
        p.AP_U_mm = float(u)
    late = overdue(cell, info.created_at)
    tolerance = cell.tolerance_mm
    if tolerance is None:
        quoted = ModelQuote.model_validate(record["model"].get("meta") or {}).validation
        tolerance = quoted.tolerance_mm if quoted is not None else None
    return VerificationDoc.model_validate(
        {
            "robot": cell.robot.name if hasattr(cell.robot, "name") else str(cell.robot),
            "model": record["model"],
            "instrument": _instrument(cell, cell.tracker if cell.simulated else None),
            "date": info.created_at.astimezone(dt.UTC).isoformat(timespec="seconds"),
            "smr": record["smr"],
            "simulated": cell.simulated,
            "campaign": info.id,
            "cycles": record["cycles"],
            "directions": record["directions"],
            "approach_mm": record["approach_mm"],
            "points": plan.names,
            "before": runs["nominal"],
            "after": runs["compensated"],
            "simulated_s": seconds if cell.simulated else None,
            "tracker_overdue": late,
            "uncertainty": {
                **model_u,
                "ap_u": AP_U,
                "decision": decision(ap, ap_u, tolerance, tracker_overdue=late),
                "rp_u": RP_U,
                # the arm's repeatability against its data sheet's (the cell's repeatability_mm)
                "rp_decision": decision(
                    [p.RP_mm for p in after],
                    [p.RP_U_above_mm for p in after],
                    cell.repeatability_mm,
                    tracker_overdue=late,
                    below=[p.RP_U_below_mm for p in after],
                    rule=RP_RULE,
                ),
            },
        }
    )


def timed_model_text(settings: dict) -> str | None:
    """The text of a verification's model whose U needs each visit's time or temperature: the
    record's, or the compensated plan's where the run solved its temperature terms (campaigns
    stored before it was kept once have both, the same); None for an untimed model."""
    return settings[RECORD].get("timed_model") or (settings.get(KEY) or {}).get("model")


def verification_json(info: store.CampaignInfo, meas: Measurements, report=None) -> dict:
    """The verification report of a done campaign as verification.json has it (the API's)."""
    return verification_report(info, meas).to_json()


def acquire_options(cell: Cell, opts: VerifyOptions, poses: int) -> AcquireOptions:
    """How the verification campaign is acquired: on the calibration's simulated arm (its seed
    and effects), read with noise of its own; under a name of its own."""
    return AcquireOptions(
        poses=poses,
        seed=opts.seed,
        name=f"{opts.name}-{dt.datetime.now(dt.UTC).strftime('%Y%m%dT%H%M%S%f')}",
        pause_s=opts.pause_s,
        samples=opts.samples,
        settle=opts.settle,
        effects=tuple(opts.effects),
        noise_seed=[opts.seed, 9283] if cell.simulated else None,
        arm=opts.arm,
    )


def certificate(info: store.CampaignInfo, meas: Measurements, report=None) -> str:
    """The accuracy certificate's HTML of a done verification campaign."""
    from robocal.server.verify.certificate import render

    return render(verification_report(info, meas))


def verify(db_path, cell: Cell, model_path, opts: VerifyOptions, log=None) -> VerificationDoc:
    """Run the nominal and the compensated verification on the cell; the verification report."""
    q_deg, labels, settings = prepare(cell, model_path, opts)
    summary = acquire(
        db_path,
        cell,
        acquire_options(cell, opts, run_poses(q_deg, settings)),
        log=log,
        poses_deg=q_deg,
        labels=labels,
        settings=settings,
    )
    if summary.state != "done":
        raise RuntimeError(f"the verification run ended {summary.state}")
    return verification_report(*readings(store.open_database(db_path), summary.campaign))


# What the certificate says of the tracker's traceability, from the cell's tracker block.
TRACEABILITY = ("serial", "certificate_id", "certificate_due", "smr_ids")


def _instrument(cell: Cell, tracker) -> dict:
    trace = {k: cell.tracker[k] for k in TRACEABILITY if cell.tracker.get(k) is not None}
    if cell.simulated:
        return {"kind": "simulated laser tracker", **(tracker or {}), **trace}
    d = cell.devices
    return {"kind": "laser tracker", "address": d.tracker_address() if d else None, **trace}


def overdue(cell: Cell, when: dt.datetime) -> str | None:
    """The tracker's calibration due date (YYYY-MM-DD) when the run was after it, else None."""
    due = cell.tracker.get("certificate_due")
    if due is None:
        return None
    return due if when.date() > dt.date.fromisoformat(str(due)) else None


def write(report: VerificationDoc, path) -> None:
    """Write verification.json whole, or not at all."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(report.to_json(), indent=2, default=_plain))
    tmp.replace(path)


def _plain(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return str(v)
