"""`robocal check`: a quick check of a deployed model, judged over that model's history.

The check's readings are compared with the model (level) and with the model's first checks
(change, accumulated by a CUSUM); what changed is named where one cause explains it: a rigid
motion of every point (the tracker or the base moved), one joint's zero, or a scale (warming).
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from robocal.server import store
from robocal.server.calibration.units import MODEL_ARM
from robocal.server.calibration.workflow import (
    DataError,
    _pose_column,
    load_campaign,
    model_predict,
)
from robocal.server.formats.cell_json import Cell
from robocal.server.formats.errors import InputError
from robocal.server.formats.model_json import (
    ModelFile,
    approach_unknown,
    file_digest,
    read_model,
)
from robocal.server.store.model_checks import CheckRecord, NewCheck, append_check
from robocal.solver import drift
from robocal.solver.gravity import DOWN
from robocal.solver.kinematics import joint_frames, predict
from robocal.solver.measurements import Measurements
from robocal.solver.vocabulary import after_campaign

EXIT_RECALIBRATE = 3
STEEL_PPM_PER_K = 11.7  # the thermal expansion of an arm's steel and cast iron
FD_STEP_RAD = 1e-6  # central differences of the model's prediction in one joint
PAYLOAD_TORQUE_SHARE = 0.1  # a joint whose gravity torque is below this share carries no load
VERDICTS = ("ok", "watch", "recalibrate")
# The most poses a check uploaded to the service takes: it is judged in the service's own thread
# (in the store's write transaction), and a quick check is a few fixed poses.
MAX_POSES = 100
# A check pose is the same pose when its joints are: a model's error differs from place to place
# by more than the scatter between checks, so an earlier check's error at a pose of the same name
# measured elsewhere (another plan's 'check1') is no baseline for it.
SAME_POSE_DEG = 0.5


@dataclass(frozen=True)
class CheckResult:
    """check.json: the contract's figures and verdict, and how the change was judged."""

    model_sha256: str
    poses: int
    rms_mm: float
    max_mm: float
    expected_rms_mm: float
    verdict: str
    reason: str
    history: int
    change_mm: float | None  # RMS change from the model's first checks (None: the first check)
    scatter_mm: float | None  # the scatter between checks it was judged against
    change_score: float
    cusum: float
    cause: str | None  # rigid, joint N, scale, unknown; None when nothing changed
    # said beside the verdict, not in check.json: the rows' order taken as the order of motion
    # for a backlash model (model_json.approach_unknown)
    warning: str | None = None

    def to_json(self) -> dict:
        out = asdict(self)
        out.pop("warning")
        for k, v in out.items():
            if isinstance(v, float):
                out[k] = round(v, 6)
        return out


@dataclass(frozen=True)
class _Readings:
    """A check's readings: keys (pose, target), joints, the model's prediction and the error."""

    keys: list[tuple[str, str]]
    q: np.ndarray  # (m, N) rad
    reading_pose: np.ndarray  # (n,) index into q
    reading_target: np.ndarray  # (n,) index into the model's targets
    predicted: np.ndarray  # (n, 3)
    error: np.ndarray  # (n, 3) measured - predicted
    # what the model's extensions read beside the joints: time and air temperature (m,) a pose,
    # the joints the arm came from (m, N) rad; None where the check has no such column
    time_s: np.ndarray | None = None
    temp_c: np.ndarray | None = None
    prev_q: np.ndarray | None = None
    approach: str | None = None  # model_json.approach_unknown: how the backlash was applied


def expected_rms(model: ModelFile) -> float:
    """The 3-D RMS a check should show: the model's held-out error (its fit's without one), and
    never below the tracker's noise; DataError if the model states neither."""
    v = model.verdict
    floor = v.noise_floor_mm or 0.0
    for figure in (v.holdout_rms_mm, v.fit_rms_mm):
        if figure is not None and np.isfinite(figure) and figure > 0:
            return max(float(figure), floor)
    raise DataError("the model states no held-out or fit error to check against: calibrate again")


def _readings(model: ModelFile, meas: Measurements, check_path) -> _Readings:
    unknown = [t for t in meas.target_names if t not in model.targets]
    if unknown:
        raise DataError(f"{check_path}: target {unknown[0]!r} is not in the model")
    names = list(model.targets)
    order = [names.index(t) for t in meas.target_names]
    time_s, temp_c = _pose_column(meas.time_s), _pose_column(meas.temp_c)
    if after_campaign(model.extensions) is not None:
        time_s = None  # the check's clock starts with the check: the cell as the campaign left it
    try:
        pred = model_predict(model, meas.q, time_s, temp_c, meas.prev_q, meas.pose_ids)
    except DataError as e:
        raise DataError(f"{check_path}: {e}") from None
    pred = pred[:, order]
    pi, ki = np.nonzero(meas.mask)
    if len(pi) == 0:
        raise DataError(f"{check_path}: no reading to check")
    return _Readings(
        [(meas.pose_ids[i], meas.target_names[k]) for i, k in zip(pi, ki)],
        meas.q,
        pi,
        np.array(order)[ki],
        pred[pi, ki],
        meas.xyz[pi, ki] - pred[pi, ki],
        time_s,
        temp_c,
        meas.prev_q,
        approach_unknown(model, meas.q, time_s, meas.prev_q, meas.pose_ids),
    )


def _matched(history: list[CheckRecord], keys) -> np.ndarray:
    """(c, n, 3) each earlier check's error at this check's readings (NaN where it lacks one)."""
    at = {k: i for i, k in enumerate(keys)}
    out = np.full((len(history), len(keys), 3), np.nan)
    for c, rec in enumerate(history):
        for pose, target, *e in rec.errors:
            i = at.get((str(pose), str(target)))
            if i is not None:
                out[c, i] = e[:3]
    return out


def moved_pose(history: list[CheckRecord], r: _Readings) -> str | None:
    """Why an earlier check's pose of a name this check uses is not the same pose (its joints,
    stored with its errors, differ by more than SAME_POSE_DEG), or None."""
    q = np.degrees(r.q)
    by_name = {pose: q[i] for (pose, _), i in zip(r.keys, r.reading_pose)}
    for rec in history:
        for pose, _target, *e in rec.errors:
            now = by_name.get(str(pose))
            if now is None or len(e) != 3 + len(now):  # a check stored without its joints
                continue
            gap = np.abs(np.asarray(e[3:], dtype=float) - now)
            if gap.max() > SAME_POSE_DEG:
                j = int(np.argmax(gap))
                return (
                    f"pose {pose!r} has q{j + 1} {now[j]:.3f} deg, but check {rec.id} of this "
                    f"model measured a pose of that name at q{j + 1} {e[3 + j]:.3f} deg: a check "
                    "measures the same poses every time, and an error measured elsewhere is no "
                    "baseline for it; give new poses new names (or check a new model)"
                )
    return None


def _joint_columns(model: ModelFile, r: _Readings) -> dict:
    """(kind, joint) -> the readings' motion (3n, k) for each candidate cause."""
    cands: dict[tuple[str, int | None], np.ndarray] = {}
    moves = []
    for j in range(r.q.shape[1]):
        step = np.zeros(r.q.shape[1])
        step[j] = FD_STEP_RAD
        # at the check's own time, temperature and motion: a thermal or backlash model
        # predicts nothing without them
        plus = model_predict(model, r.q + step, r.time_s, r.temp_c, r.prev_q)
        minus = model_predict(model, r.q - step, r.time_s, r.temp_c, r.prev_q)
        col = (plus - minus)[r.reading_pose, r.reading_target] / (2 * FD_STEP_RAD)
        moves.append(col)
        if np.linalg.norm(col) > 0:
            cands[("joint", j + 1)] = col.reshape(-1, 1)
    origin = model.base[:3, 3]
    cands[("scale", None)] = (r.predicted - origin).reshape(-1, 1)
    cands[("payload", None)] = _payload_columns(model, r, moves)
    cands[("rigid", None)] = drift.rigid_columns(r.predicted)
    return cands


def _payload_columns(model: ModelFile, r: _Readings, moves) -> np.ndarray:
    """A payload's change: each loaded joint gives way in proportion to the gravity torque of a
    mass at the SMRs (its compliance unknown), one column a joint whose torque matters."""
    lay, x = model.layout()
    frames = joint_frames(lay, x, r.q)
    # gravity along the levelled tracker's -z (the frames are the tracker's), as the solver's
    # compliance takes it (solver.gravity): on a wall- or ceiling-mounted arm the base's -z is not
    down = DOWN
    centre = predict(lay, x, r.q).mean(axis=1)
    torque = np.array(
        [np.einsum("mi,mi->m", R[:, :, 2], np.cross(centre - o, down)) for R, o in frames]
    )  # (N, m), N m per N of weight
    loaded = np.abs(torque).max(axis=1) > PAYLOAD_TORQUE_SHARE * np.abs(torque).max()
    cols = [moves[j] * torque[j][r.reading_pose][:, None] for j in np.flatnonzero(loaded)]
    return np.column_stack([c.ravel() for c in cols])


def _cause(found: list[drift.Explanation]) -> tuple[str, str]:
    """The cause's name and what a person should do about it, in a sentence."""
    if not found:
        return "unknown", (
            "no single cause (a rigid motion, one joint's zero, a scale, a payload) explains it: "
            "recalibrate"
        )
    if len(found) > 1:
        named = ", ".join(_name(e) for e in found[:3])
        return "unknown", f"{named} would each explain it and the check cannot tell: recalibrate"
    e = found[0]
    if e.kind == "rigid":
        turn = float(np.degrees(np.linalg.norm(e.values[:3])))
        move = float(np.linalg.norm(e.values[3:]))
        return "rigid", (
            f"every point moved as one rigid body ({move:.3f} mm, {turn:.4f} deg; "
            f"{e.rms_left_mm:.3f} mm left): the tracker or the base moved; re-registering the "
            "base suffices, no recalibration of the arm"
        )
    if e.kind == "joint":
        mdeg = float(np.degrees(e.values[0]) * 1000.0)
        return f"joint {e.joint}", (
            f"joint {e.joint}'s zero moved by {mdeg:+.1f} mdeg ({e.rms_left_mm:.3f} mm left): a "
            f"gear, encoder or motor change; recalibrate joint {e.joint}'s offset"
        )
    if e.kind == "payload":
        return "payload", (
            f"the loaded joints gave way in proportion to their gravity torque "
            f"({e.rms_left_mm:.3f} mm left): the payload or the tool changed; set the controller's "
            "load data to the new payload, or recalibrate with it"
        )
    ppm = float(e.values[0] * 1e6)
    return "scale", (
        f"every point moved away from the base in proportion, {ppm:+.0f} ppm "
        f"({e.rms_left_mm:.3f} mm left): a temperature change of about "
        f"{ppm / STEEL_PPM_PER_K:+.1f} K in the arm, or the tracker's scale; check at the "
        "calibration's temperature or recalibrate"
    )


def _name(e: drift.Explanation) -> str:
    names = {"rigid": "a rigid motion", "scale": "a scale", "payload": "a payload change"}
    return names.get(e.kind, f"joint {e.joint}'s zero")


def judge(model: ModelFile, r: _Readings, history: list[CheckRecord], expected: float):
    """The check's NewCheck and the figures of its change, from the model and its history."""
    lvl = drift.level(r.error, r.reading_pose, expected)
    floor = model.verdict.noise_floor_mm or 0.0
    prior = max(floor, drift.REPEATABILITY_MM)
    change = None
    if history:
        H = _matched(history, r.keys)
        stats = [(c.change_z, c.cusum) for c in history]
        seen = np.isfinite(H[: drift.baseline_checks(stats), :, 0]).any(axis=0)
        if seen.sum() >= 2:
            # Each pose's mean error is one vector: its SMRs share the arm's scatter.
            at = r.reading_pose[seen]
            change = drift.since_baseline(
                _by_pose(r.error[seen], at), _by_pose(H[:, seen], at), stats, prior
            )
    verdict = max(lvl.verdict, change.verdict if change else "ok", key=VERDICTS.index)
    n_poses = len(np.unique(r.reading_pose))
    said = (
        f"{lvl.rms_mm:.3f} mm RMS (max {lvl.max_mm:.3f}) on {n_poses} poses against the "
        f"model's expected {expected:.3f} mm"
    )
    beyond = _beyond_tolerance(model, r)
    if beyond:
        verdict = "recalibrate"
        said = f"{beyond}; {said}"
    elif not model.verdict.deployable:
        said = f"{said}; {model.verdict.refusal()}"
    cause = None
    if change is None:
        said += "; the first check of this model, which later checks are compared with"
    else:
        said += (
            f"; {change.rms_mm:.3f} mm from the model's first checks, against "
            f"{change.scatter_mm:.3f} mm of scatter between checks"
        )
    found = None
    if change is not None and change.verdict != "ok":
        sub = _subset(r, seen)
        cols = _joint_columns(model, sub)
        cols = {k: _pose_columns(c, sub.reading_pose, change.compared) for k, c in cols.items()}
        found = drift.explain(change.diff, change.var_change, cols)
        why = f" ({_trend(change)})"
    elif lvl.verdict != "ok":
        every = np.ones(n_poses, dtype=bool)
        cols = {
            k: _pose_columns(c, r.reading_pose, every) for k, c in _joint_columns(model, r).items()
        }
        found = drift.explain(_by_pose(r.error, r.reading_pose), expected**2 / 3.0, cols)
        why = f" ({lvl.rms_mm / expected:.1f}x the model's expected error)"
    if found is not None and verdict == "recalibrate":
        cause, action = _cause(found)
        said += f"{why}: {action}"
    elif found is not None:  # watch
        like = f", like {_name(found[0])}" if len(found) == 1 else ""
        said += f"{why}: a change that may be scatter{like}; check again soon"
    # each reading's joints beside its error, so a later check can tell the same pose from
    # another of the same name
    q = np.round(np.degrees(r.q[r.reading_pose]), 6)
    errors = [
        [p, t, *np.round(e, 6).tolist(), *qq.tolist()] for (p, t), e, qq in zip(r.keys, r.error, q)
    ]
    new = NewCheck(
        source="",
        poses=n_poses,
        rms_mm=lvl.rms_mm,
        max_mm=lvl.max_mm,
        expected_rms_mm=expected,
        change_z=change.z if change else 0.0,
        cusum=change.cusum if change else 0.0,
        verdict=verdict,
        reason=said,
        errors=errors,
    )
    return new, change, cause


def _beyond_tolerance(model: ModelFile, r: _Readings) -> str | None:
    """Why the check's error is beyond the tolerance the model was validated against (the
    application's accuracy, its validation's tolerance_mm), at the level test's confidence; None
    within it or without one. A model past its tolerance passed every check 'ok' against its own
    held-out error (0.91 mm RMS a check where the tolerance was 0.05 mm)."""
    tol = model.verdict.tolerance_mm
    if tol is None:
        return None
    if drift.level(r.error, r.reading_pose, tol).verdict != "recalibrate":
        return None
    return (
        f"beyond the tolerance {tol:g} mm the model was validated against (the accuracy the "
        "application needs): recalibrate"
    )


def _by_pose(E: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(..., P, 3) each pose's mean error over its readings E (..., n, 3) (NaN where none)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a pose an earlier check lacks
        return np.stack([np.nanmean(E[..., pose == p, :], axis=-2) for p in np.unique(pose)], -2)


def _pose_columns(cols: np.ndarray, pose: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """A cause's columns (3n, k) over readings as the pose means _by_pose takes, kept poses."""
    k = cols.shape[1]
    by = _by_pose(np.moveaxis(cols.reshape(-1, 3, k), 2, 0), pose)[:, keep]
    return np.moveaxis(by, 0, 2).reshape(-1, k)


def _trend(change: drift.Change) -> str:
    return f"change score {change.z:.1f}, accumulated {change.cusum:.1f}"


def _subset(r: _Readings, keep: np.ndarray) -> _Readings:
    return _Readings(
        [k for k, s in zip(r.keys, keep) if s],
        r.q,
        r.reading_pose[keep],
        r.reading_target[keep],
        r.predicted[keep],
        r.error[keep],
        r.time_s,
        r.temp_c,
        r.prev_q,
    )


@dataclass(frozen=True)
class Prepared:
    """A check read against its model, ready to be judged over the model's history."""

    model: ModelFile
    model_sha256: str
    expected_rms_mm: float
    readings: _Readings


def prepare(model_path, check_path) -> Prepared:
    """The model and the check's readings against it (DataError / InputError if they do not
    fit): the heavy part, parsed where the caller likes (the service: a worker process)."""
    model = read_model(model_path)
    expected = expected_rms(model)
    cell = Cell(model.robot, model.targets, None, {}, None)
    meas = load_campaign(check_path, cell, arm=MODEL_ARM)
    return Prepared(model, file_digest(model_path), expected, _readings(model, meas, check_path))


def prepare_measured(model: ModelFile, sha: str, meas: Measurements, where: str) -> Prepared:
    """A model (its file's sha256) and a check's readings measured into the store (`where` they
    are, for messages), ready to be judged: `acquire --check`."""
    return Prepared(model, sha, expected_rms(model), _readings(model, meas, where))


def record(db: store.Database, p: Prepared, source: str) -> CheckResult:
    """Judge a prepared check over its model's history and append it there; the result."""
    out: dict = {}

    def judged(history: list[CheckRecord]) -> NewCheck:
        moved = moved_pose(history, p.readings)
        if moved:
            raise InputError(source, None, None, moved)
        new, change, cause = judge(p.model, p.readings, history, p.expected_rms_mm)
        out.update(change=change, cause=cause)
        return NewCheck(**{**vars(new), "source": source})

    history = append_check(db, p.model_sha256, judged)
    last, change = history[-1], out["change"]
    return CheckResult(
        model_sha256=p.model_sha256,
        poses=last.poses,
        rms_mm=last.rms_mm,
        max_mm=last.max_mm,
        expected_rms_mm=last.expected_rms_mm,
        verdict=last.verdict,
        reason=last.reason,
        history=len(history),
        change_mm=change.rms_mm if change else None,
        scatter_mm=change.scatter_mm if change else None,
        change_score=last.change_z,
        cusum=last.cusum,
        cause=out["cause"],
        warning=p.readings.approach,
    )


def run_check(model_path, check_path, db: store.Database) -> CheckResult:
    """Check a model on a check campaign, append it to the model's history; the result."""
    return record(db, prepare(model_path, check_path), Path(check_path).name)
