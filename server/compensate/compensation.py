"""`robocal compensate`: a model file and a targets file in, joint commands out."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from robocal.server.formats.errors import InputError
from robocal.server.formats.model_json import (
    ModelFile,
    approach_unknown,
    extrapolated,
    read_model,
)
from robocal.server.formats.targets_csv import Targets, read_targets
from robocal.solver import configuration
from robocal.solver.compensate import Compensation, Model, compensate
from robocal.solver.kinematics import Layout, rot
from robocal.solver.plausibility import radian_guess_misses
from robocal.solver.vocabulary import after_campaign

TCP_NAME = "TCP"  # the virtual SMR's name in targets.csv when a tool centre point is given
# an oriented tool is three virtual SMRs: its point and points this far along its x and z axes
LEVER_MM = 100.0
TOOL_POINTS = (TCP_NAME, "TCP_X", "TCP_Z")
MAX_ERROR_MM = 0.1  # a pose the model cannot bring closer than this is refused as unreachable
# a correction moves joints by hundredths of a degree: a joint that moved further than this from
# its starting guess took the arm to another configuration (or the guess is not this pose's)
MAX_MOVE_DEG = 10.0
MAX_JUMP_DEG = 90.0  # consecutive poses whose joints turn more than this are reported
ORIENTING_SMRS = 3  # SMRs that fix the flange's orientation
# SMRs closer than this (RMS) to one line fix no roll about it: 0.1 mm of the tracker's noise
# over 1 mm is 6 degrees
LINE_MM = 1.0


def parse_tcp(text: str) -> list[float]:
    """x,y,z[,rx,ry,rz] (mm, degrees) of a tool centre point in the flange frame; ValueError."""
    try:
        v = [float(p) for p in text.split(",")]
    except ValueError:
        v = []
    if len(v) not in (3, 6) or not all(np.isfinite(v)) or max(abs(c) for c in v) > 10_000:
        raise ValueError(
            f"{text!r} is not x,y,z[,rx,ry,rz]: the tool centre point in the flange frame, mm, "
            "and its orientation, degrees"
        )
    return v


def rotation(rx, ry, rz) -> np.ndarray:
    """Rz(rz) Ry(ry) Rx(rx), angles in degrees (KUKA's A, B, C order)."""
    return (rot(2, np.deg2rad(rz)) @ rot(1, np.deg2rad(ry)) @ rot(0, np.deg2rad(rx)))[:3, :3]


def tool_points(point, R) -> np.ndarray:
    """A tool frame (point (3,), rotation R (3, 3)) as its three virtual SMRs (3, 3)."""
    point = np.asarray(point, dtype=float)
    return np.array([point, point + LEVER_MM * R[:, 0], point + LEVER_MM * R[:, 2]])


def solver_model(model: ModelFile, tcp=None) -> Model:
    """The model file as the solver takes it; with tcp (x, y, z[, rx, ry, rz]) mm and degrees in
    the flange frame, the tool's three virtual SMRs (TOOL_POINTS) in place of the SMRs."""
    if tcp is None:
        lay, x = model.layout()
    else:
        tcp = list(tcp) + [0.0] * (6 - len(tcp))
        lay = Layout(model.robot, model.base, TOOL_POINTS)
        x = lay.initial(tool_points(tcp[:3], rotation(*tcp[3:])))
    return Model(lay, x, list(model.extensions), model.nominal or model.robot)


def tool_targets(targets: Targets) -> Targets:
    """targets.csv's TCP rows as the tool's virtual SMRs: its point, and where a pose gives the
    tool's orientation (rx, ry, rz in the cell frame), the points along its x and z axes."""
    m = len(targets.pose_ids)
    p = targets.desired[:, 0]
    desired = np.repeat(p[:, None], 3, axis=1)
    mask = np.zeros((m, 3), dtype=bool)
    mask[:, 0] = targets.mask[:, 0]
    turn = targets.orientation if targets.orientation is not None else np.full((m, 3), np.nan)
    for k in np.flatnonzero(np.all(np.isfinite(turn), axis=1)):
        desired[k] = tool_points(p[k], rotation(*turn[k]))
        mask[k] = True
    wide = lambda a: None if a is None else np.repeat(a[:, :1], 3, axis=1)  # noqa: E731
    return replace(
        targets,
        names=TOOL_POINTS,
        desired=desired,
        mask=mask,
        time_s=wide(targets.time_s),
        temp_c=wide(targets.temp_c),
    )


@dataclass(frozen=True)
class Jump:
    """Consecutive poses (file order) between which a joint turns further than the set limit."""

    before: str
    after: str
    joint: int  # 1-based
    deg: float

    def describe(self) -> str:
        return f"{self.before!r} -> {self.after!r}: joint {self.joint} turns {self.deg:.1f} deg"


@dataclass(frozen=True)
class Compensated:
    """A targets file's joint commands (m, n) deg, their predicted miss (m,) mm, the warnings
    (one line each, about the targets file) and the jumps between consecutive poses beyond the
    limit."""

    pose_ids: list[str]
    q_deg: np.ndarray
    error_mm: np.ndarray
    warnings: list[str]
    jumps: list[Jump]


def compensate_targets(
    model: ModelFile,
    targets: Targets,
    tcp=None,
    max_error_mm: float = MAX_ERROR_MM,
    max_move_deg: float = MAX_MOVE_DEG,
) -> tuple[Compensation, list[str]]:
    """The joint commands for these targets and the warnings; InputError naming the file, line
    and pose of the first one given neither starting joints nor a configuration, that the model
    cannot reach within the limits (in that configuration), or whose solution would leave its
    starting joints' configuration."""
    later = after_campaign(model.extensions)
    if targets.time_s is None and later is not None:
        # the program runs after the campaign: the cell as the campaign left it (moved)
        targets = replace(targets, time_s=np.full(targets.mask.shape, later))
    for e in model.extensions:
        need = e.kind.needs(e)
        if need and getattr(targets, need) is None:
            raise InputError(
                targets.path,
                1,
                None,
                f"the model's {e.label()} needs a {need} column (the {need} the program runs at)",
            )
        if need and not np.all(np.isfinite(getattr(targets, need))):
            k = int(np.flatnonzero(~np.all(np.isfinite(getattr(targets, need)), axis=1))[0])
            raise InputError(
                targets.path,
                targets.lines[k],
                None,
                f"pose {targets.pose_ids[k]!r}: the model's {e.label()} needs its {need}",
            )
    guess = np.all(np.isfinite(targets.q0), axis=1)
    cf = targets.cf if targets.cf is not None else np.full((len(guess), 4), np.nan)
    given = np.all(np.isfinite(cf), axis=1)
    _refuse_first(
        targets,
        ~guess & ~given,
        "has neither starting joints (q1 ... qN) nor a configuration (cf1, cf4, cf6, cfx): "
        "an arm reaches most positions in several configurations, and none is chosen for you",
    )
    nominal = model.nominal or model.robot
    if (guess & given).any():
        have = np.full(cf.shape, np.nan)
        have[guess & given] = configuration.confdata(nominal, targets.q0[guess & given])
        clash = guess & given & np.any(have != cf, axis=1)
        k = int(np.flatnonzero(clash)[0]) if clash.any() else -1
        if k >= 0:
            raise _pose_error(
                targets,
                k,
                f"has starting joints in configuration {configuration.describe(have[k])} but "
                f"cf columns {configuration.describe(cf[k])}",
            )
    if tcp is None:
        _refuse_other_units(targets, guess, model, nominal)
    warnings = _orientation_warnings(targets, guess, tcp)
    if tcp is not None:
        targets = tool_targets(targets)
    solver = solver_model(model, tcp)
    res = compensate(
        solver,
        targets.desired,
        targets.mask,
        targets.q0,
        targets.time_s,
        targets.temp_c,
        cf=np.where(guess[:, None], np.nan, cf),
        prev_q=targets.prev_q,
    )
    _refuse_first(
        targets,
        ~np.isfinite(res.error_mm),
        f"has no solution in its configuration within the joint limits{_more_none(res)}",
    )
    bad = np.flatnonzero(~(res.error_mm <= max_error_mm))
    if len(bad):
        k = int(bad[0])
        raise _pose_error(
            targets,
            k,
            f"is unreachable within the joint limits: the model comes no closer than "
            f"{res.error_mm[k]:.3f} mm RMS (at most {max_error_mm:g} mm allowed){_more(len(bad))}"
            + _elsewhere(res.error_mm, len(bad)),
        )
    if guess.any():
        warnings += _kept(targets, res, guess, solver, max_move_deg)
    if open_turn := _open_turns(targets, nominal, ~guess & given):
        warnings.append(open_turn)
    beyond = extrapolated(model, res.q, targets.pose_ids)
    if beyond:
        warnings.append(beyond)
    if unknown := approach_unknown(model, res.q, targets.time_s, targets.prev_q, targets.pose_ids):
        warnings.append(unknown)
    return res, warnings


def _open_turns(targets: Targets, nominal, alone: np.ndarray) -> str | None:
    """A warning when poses asked for by confdata alone have joints it leaves a turn open on (a
    UR-like arm's +-360 deg joints 2 and 3): the solver took the turn nearest zero."""
    joints = configuration.open_turns(nominal)
    if not joints or not alone.any():
        return None
    k = int(np.flatnonzero(alone)[0])
    names = " and ".join(str(j + 1) for j in joints)
    plural = "s" if len(joints) > 1 else ""
    ranges = ", ".join(
        f"{np.degrees(nominal.lower[j]):g} to {np.degrees(nominal.upper[j]):g}" for j in joints
    )
    return (
        f"{int(alone.sum())} poses (first {targets.pose_ids[k]!r}) give a "
        f"configuration (cf1, cf4, cf6, cfx) alone, which holds joints 1, 4 and 6 to a quadrant; "
        f"{nominal.name}'s joint{plural} {names} can turn more than a full turn within the "
        f"limits ({ranges} deg), a turn confdata leaves open: taken at the angle nearest zero; "
        f"give starting joints "
        f"q1 ... q{nominal.n_joints} for another turn"
    )


# every pose missed by this much or more: no arm's error, the targets are in another frame
ELSEWHERE_MM = 100.0


def _elsewhere(error_mm: np.ndarray, bad: int) -> str:
    """A clause when every pose is missed by ELSEWHERE_MM or more (targets from another
    campaign's tracker frame, or in other units), empty otherwise."""
    if bad < len(error_mm) or not np.min(error_mm) >= ELSEWHERE_MM:
        return ""
    return (
        f"; every pose misses by {np.min(error_mm):.0f} mm or more: are the targets in this "
        "model's tracker frame (measured with the tracker where it stood for the calibration)?"
    )


def _pose_error(targets: Targets, k: int, what: str) -> InputError:
    return InputError(targets.path, targets.lines[k], None, f"pose {targets.pose_ids[k]!r} {what}")


def _refuse_first(targets: Targets, bad: np.ndarray, what: str) -> None:
    if bad.any():
        raise _pose_error(targets, int(np.flatnonzero(bad)[0]), what)


def _more_none(res: Compensation) -> str:
    count = int(np.sum(~np.isfinite(res.error_mm)))
    return f"; {count - 1} more poses have none" if count > 1 else ""


def _refuse_other_units(targets: Targets, guess, model: ModelFile, nominal) -> None:
    """InputError naming the likely units of targets in metres or inches, or of starting joints
    in radians: their spread is not the nominal arm's at the starting joints (the campaign's
    check, solver.plausibility); such targets were 'unreachable' by metres."""
    from robocal.solver.plausibility import check_units

    if not guess.any() or any(n not in model.targets for n in targets.names):
        return
    smrs = np.array([model.targets[n] for n in targets.names], dtype=float)
    xyz = np.where(targets.mask[..., None], targets.desired, np.nan)[guess]
    why = check_units(nominal, smrs, targets.q0[guess], xyz).reason("targets", "starting")
    if why:
        raise InputError(targets.path, None, None, why)


def _orientation_warnings(targets: Targets, guess: np.ndarray, tcp) -> list[str]:
    """One line for the poses whose targets leave the flange's orientation free: fewer than three
    SMRs (or a tool point without rx, ry, rz)."""
    if tcp is not None:
        oriented = (
            np.all(np.isfinite(targets.orientation), axis=1)
            if targets.orientation is not None
            else np.zeros(len(guess), dtype=bool)
        )
        free = ~oriented
    else:
        free = (targets.mask.sum(axis=1) < ORIENTING_SMRS) | _on_a_line(targets)
    if not free.any():
        return []
    ids = [targets.pose_ids[k] for k in np.flatnonzero(free)]
    source = (
        "the starting joints"
        if guess[free].all()
        else "the starting joints or the configuration's search"
    )
    return [
        f"{len(ids)} poses (first {ids[0]!r}) give too few SMRs (or SMRs on one line) to fix "
        f"the flange's orientation: it comes from {source}, not from the targets"
    ]


def _on_a_line(targets: Targets) -> np.ndarray:
    """Per pose, whether its desired SMRs lie within LINE_MM (RMS) of one line: the roll about
    it is then as free as with one SMR."""
    out = np.zeros(len(targets.mask), dtype=bool)
    for k, (xyz, given) in enumerate(zip(targets.desired, targets.mask)):
        p = xyz[given]
        if len(p) >= ORIENTING_SMRS:
            s = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
            out[k] = s[1] / np.sqrt(len(p)) < LINE_MM
    return out


def _kept(
    targets: Targets, res: Compensation, guess, solver: Model, max_move_deg: float
) -> list[str]:
    """Refuse a pose whose joints moved further from its starting guess than max_move_deg (the
    solver left the guess's configuration), naming radians when they explain the guess; one
    warning for those whose confdata changed within that (a guess by a quadrant's edge)."""
    moved = np.where(guess[:, None], np.degrees(np.abs(res.q - targets.q0)), 0.0)
    far = np.flatnonzero(moved.max(axis=1) > max_move_deg)
    if len(far):
        k = int(far[0])
        j = int(np.argmax(moved[k]))
        why = "a correction needs far less: check the starting joints"
        if miss := radian_guess_misses(
            solver.layout, solver.x, targets.q0[k], targets.desired[k], targets.mask[k]
        ):
            why = (
                f"the model misses the targets by {miss[0]:.3g} mm at the starting joints, "
                f"{miss[1]:.3g} mm with them read as radians: q1..q{len(targets.q0[k])} look "
                "like radians: give them in degrees"
            )
        raise _pose_error(
            targets,
            k,
            f"would leave its starting joints' configuration: joint {j + 1} moves "
            f"{moved[k, j]:.1f} deg (more than {max_move_deg:g} deg; {why}){_more(len(far))}",
        )
    nominal = solver.nominal
    if not configuration.supports(nominal):
        return []
    before = configuration.confdata(nominal, targets.q0[guess])
    after = configuration.confdata(nominal, res.q[guess])
    changed = np.flatnonzero(np.any(before != after, axis=1))
    if not len(changed):
        return []
    k = int(np.flatnonzero(guess)[changed[0]])
    return [
        f"{len(changed)} poses (first {targets.pose_ids[k]!r}, "
        f"{configuration.describe(before[changed[0]])} -> "
        f"{configuration.describe(after[changed[0]])}) cross a configuration boundary within "
        f"{max_move_deg:g} deg of their starting joints"
    ]


def jumps(pose_ids, q_deg, limit_deg: float = MAX_JUMP_DEG) -> list[Jump]:
    """Consecutive poses (in file order) between which some joint turns more than limit_deg: the
    largest such turn of each pair."""
    q_deg = np.asarray(q_deg, dtype=float)
    step = np.abs(np.diff(q_deg, axis=0))
    out = []
    for k in np.flatnonzero(step.max(axis=1, initial=0.0) > limit_deg) if len(step) else []:
        j = int(np.argmax(step[k]))
        out.append(Jump(str(pose_ids[k]), str(pose_ids[k + 1]), j + 1, float(step[k, j])))
    return out


def _more(count: int) -> str:
    return f"; {count - 1} more poses unreachable" if count > 1 else ""


@dataclass(frozen=True)
class Limits:
    """What a compensation refuses (a miss, a move from the starting joints) and reports (a jump
    between consecutive poses)."""

    max_error_mm: float = MAX_ERROR_MM
    max_move_deg: float = MAX_MOVE_DEG
    max_jump_deg: float = MAX_JUMP_DEG


def compensate_file(model_path, targets_path, tcp=None, limits: Limits = Limits()) -> Compensated:
    """The joint commands for a model file and a targets.csv; tcp (x, y, z[, rx, ry, rz]) mm and
    degrees in the flange frame makes `TCP` the one target, with an optional orientation per pose
    (rx, ry, rz columns). InputError on bad input, a pose without a configuration, or an
    unreachable pose (nothing is written here either way)."""
    model = read_model(model_path)
    names = (TCP_NAME,) if tcp is not None else tuple(model.targets)
    targets = read_targets(targets_path, model.robot, names, orientation=tcp is not None)
    res, warnings = compensate_targets(
        model, targets, tcp, limits.max_error_mm, limits.max_move_deg
    )
    q_deg = np.rad2deg(res.q)
    found = jumps(targets.pose_ids, q_deg, limits.max_jump_deg)
    return Compensated(targets.pose_ids, q_deg, res.error_mm, warnings, found)


def run(model_path, targets_path, out_path, tcp=None, limits: Limits = Limits()) -> dict:
    """Compensate and write joints.csv; returns a summary dict for the command's line."""
    from robocal.server.formats.joints_csv import write_joints

    t0 = time.perf_counter()
    c = compensate_file(model_path, targets_path, tcp, limits)
    write_joints(out_path, c.pose_ids, c.q_deg, c.error_mm)
    return {
        "poses": len(c.pose_ids),
        "worst_mm": float(c.error_mm.max()),
        "rms_mm": float(np.sqrt(np.mean(c.error_mm**2))),
        "seconds": time.perf_counter() - t0,
        "warnings": c.warnings,
        "jumps": jumps_line(c.jumps, limits.max_jump_deg) if c.jumps else "",
    }


def jumps_line(found: list[Jump], limit_deg: float, shown: int = 5) -> str:
    """The jumps in one line for a summary."""
    more = "; ..." if len(found) > shown else ""
    return (
        f"{len(found)} jumps of more than {limit_deg:g} deg between consecutive poses: "
        + "; ".join(j.describe() for j in found[:shown])
        + more
    )
