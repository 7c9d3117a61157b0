"""Measurement campaigns (`meas.csv`), poses to predict (`poses.csv`) and predictions (`pred.csv`)."""

from __future__ import annotations

import csv
import io
from collections.abc import Collection, Sequence

import numpy as np

from robocal.solver.measurements import Measurements
from robocal.solver.robot import Robot

from .campaign_columns import read_campaign_columns, read_poses_columns
from .cell_json import TARGET_NAME
from .csv_table import Row, Table
from .errors import InputError
from .files import atomic_write_text, read_text
from .limits import COORD_MAX_MM, SMRS_MAX, TEMP_RANGE_C, TIME_MAX_S

# Rows of one pose come from one controller reading; anything beyond print rounding is a mix-up.
SAME_POSE_TOL_DEG = 1e-6
# Limits are stored in radians; a reading exactly at a limit must survive the round trip.
LIMIT_TOL_DEG = 1e-6
MEASURED = ("x", "y", "z")
EXTRAS = ("time_s", "temp_c")
# Each column's range and why: no finite-but-absurd value may reach the numerics.
BOUNDS = {
    **{c: ((-COORD_MAX_MM, COORD_MAX_MM), "mm (beyond any tracker's range)") for c in MEASURED},
    "time_s": ((-TIME_MAX_S, TIME_MAX_S), "s (30 years)"),
    "temp_c": (TEMP_RANGE_C, "degC (air at the tracker)"),
}


def joint_columns(robot: Robot) -> list[str]:
    """The joint column names `q1` ... `qN` for this robot."""
    return [f"q{i}" for i in range(1, robot.n_joints + 1)]


def joint_deg(t: Table, row: Row, i: int, name: str, robot: Robot) -> float:
    """Joint i's value (degrees) in the row's column `name`, refused outside the joint limits."""
    value = t.number(row, name)
    lo, hi = np.rad2deg(robot.lower[i]), np.rad2deg(robot.upper[i])
    if value < lo - LIMIT_TOL_DEG or value > hi + LIMIT_TOL_DEG:
        raise t.error(
            row,
            name,
            f"{t.raw(row, name)} deg is outside the limits "
            f"[{lo:.6g}, {hi:.6g}] deg of joint {i + 1} of {robot.name}"
            + _radians_hint(t, row, name.removesuffix(str(i + 1)), robot),
        )
    return value


def _radians_hint(t: Table, row: Row, prefix: str, robot: Robot) -> str:
    """What a row whose joints all lie within one turn in radians looks like: a joint limit that
    excludes small angles (a 7-axis elbow's [-176, -4] deg) stops such a file before the
    campaign's units check can name them."""
    names = [f"{prefix}{k}" for k in range(1, robot.n_joints + 1)]
    try:
        values = [t.number(row, c) for c in names]
    except (InputError, KeyError):
        return ""
    if max(abs(v) for v in values) > 2 * np.pi:
        return ""
    return (
        f"; the row's {names[0]}..{names[-1]} all lie within +-{2 * np.pi:.2f}: they look like "
        "radians; give them in degrees"
    )


def prev_columns(robot: Robot) -> list[str]:
    """The columns `prev_q1` ... `prev_qN`: the joints the arm came from before a pose."""
    return [f"prev_{c}" for c in joint_columns(robot)]


def prev_header(t: Table, robot: Robot) -> list[str]:
    """The prev_q columns present: all of them or none."""
    cols = prev_columns(robot)
    have = t.optional(cols)
    if have and len(have) != len(cols):
        missing = next(c for c in cols if c not in have)
        raise InputError(
            t.path,
            t.header_line,
            None,
            f"missing column '{missing}': the joints the arm came from give every joint, "
            f"prev_q1 to prev_q{len(cols)}",
        )
    return have


# prev_q1..prev_qN in other units than q1..qN (radians beside degrees). An arm comes to a pose
# from nearby poses of its plan (the previous pose, an approach point) or from one place (home):
# the joints it comes from spread about as much as the poses do, or not at all; in radians they
# spread 1/57.3 as much, all within the joints' limits read as radians. Measured with prev_q the
# previous pose's joints on the real IRB 120, QKM and UR5 campaigns: spread ratios 0.92-1.15 on
# 30-pose subsets, 0.40-2.6 on 3-pose ones (99% of 2,000 each); so radians fall within
# PREV_UNIT_BAND of 1/57.3 on all 5-pose subsets and 99.75% of 3-pose ones, and poses that
# always come from home (a ratio of 0) or an approach point beside them (about 1) never do.
PREV_UNIT_BAND = 3.0  # a ratio within this factor of 1/57.3 (or 57.3) is the other unit
PREV_MIN_POSES = 3  # never on one pose alone (the first pose's prev_q: home at zero joints)
PREV_MIN_SPAN_DEG = 20.0  # the degrees' joints move this much: their spread means something


def spread_ratio(small: np.ndarray, big: np.ndarray) -> float:
    """RMS spread of the rows of small (poses, n) over that of big (the same poses)."""
    s_big = float(np.sqrt(np.sum(np.var(big, axis=0))))
    return float(np.sqrt(np.sum(np.var(small, axis=0)))) / s_big if s_big > 0 else float("nan")


def looks_like_radians(small: np.ndarray, big: np.ndarray, robot: Robot) -> bool:
    """Whether joints small (poses, n, as read) are radians where big (the same poses) are
    degrees: every value of small within the joint limits in radians, big moving at least
    PREV_MIN_SPAN_DEG, and small spreading 1/57.3 as much as big (PREV_UNIT_BAND)."""
    if len(small) < PREV_MIN_POSES or np.ptp(big, axis=0).max() < PREV_MIN_SPAN_DEG:
        return False
    if np.any(small < robot.lower - LIMIT_TOL_DEG) or np.any(small > robot.upper + LIMIT_TOL_DEG):
        return False
    ratio = spread_ratio(small, big) * np.rad2deg(1.0)
    return 1 / PREV_UNIT_BAND <= ratio <= PREV_UNIT_BAND


# On one or two poses a spread says nothing, but each pose's own joints may: an arm touring its
# poses comes to each from one near it, so prev_q read as radians lies near q, read as degrees
# (within the joint limits read as radians: a few degrees from the zero pose) far from it.
# Measured with prev_q the previous pose's on the real campaigns: in radians, 733 of the UR5
# tour's 999 single poses (10-50 deg between poses) lie PREV_NEAR_BAND times nearer, none of the
# IRB 120's and QKM's (random orders, 94-333 deg between poses: nothing tells the units there);
# in degrees none of their 3,081 poses lies within the limits read as radians, and of 55,000
# draws of an arm coming to them from within 0.1-6 deg of the zero pose (home jogged) none is
# nearer (3 at a band of 3). A pose from exactly zero joints (home) says nothing either way.
PREV_NEAR_BAND = 5.0


def few_look_like_radians(small: np.ndarray, big: np.ndarray, robot: Robot) -> bool:
    """On fewer than PREV_MIN_POSES poses: whether small (poses, n, as read) are radians where
    big are degrees: every value of small within the joint limits in radians, big beyond a turn
    in radians on some joint, and every pose whose small is not all zero (at least one) nearer
    big read as radians than read as degrees by PREV_NEAR_BAND."""
    if np.any(small < robot.lower - LIMIT_TOL_DEG) or np.any(small > robot.upper + LIMIT_TOL_DEG):
        return False
    speaks = np.abs(small).max(axis=1) > LIMIT_TOL_DEG
    if np.abs(big).max() <= 2 * np.pi or not speaks.any():
        return False
    as_rad = np.linalg.norm(big - np.rad2deg(small), axis=1)[speaks]
    return bool(np.all(PREV_NEAR_BAND * as_rad < np.linalg.norm(big - small, axis=1)[speaks]))


class PrevJoints:
    """Each pose's prev_q (degrees, or None), the same on every row of the pose."""

    def __init__(self, table: Table, robot: Robot, have: list[str]):
        self.table, self.robot, self.have = table, robot, have
        self.by_pose: dict[int, tuple[Row, list[float] | None]] = {}

    def add(self, row: Row, k: int, pid: str) -> None:
        if not self.have:
            return
        t = self.table
        given = [c for c in self.have if t.raw(row, c)]
        if given and len(given) != len(self.have):
            blank = next(c for c in self.have if not t.raw(row, c))
            raise t.error(row, blank, "empty field: a row gives all of prev_q1 ... or none")
        v = (
            [joint_deg(t, row, i, c, self.robot) for i, c in enumerate(self.have)]
            if given
            else None
        )
        if k not in self.by_pose:
            self.by_pose[k] = (row, v)
            return
        first, w = self.by_pose[k]
        if (v is None) != (w is None) or (
            v is not None
            and w is not None
            and max(abs(a - b) for a, b in zip(v, w)) > SAME_POSE_TOL_DEG
        ):
            differs = (
                next(c for c, a, b in zip(self.have, v, w) if abs(a - b) > SAME_POSE_TOL_DEG)
                if v is not None and w is not None
                else self.have[0]
            )
            raise t.error(
                row,
                differs,
                f"the joints the arm came from differ from line {first.line}, an earlier row of "
                f"pose {pid!r}",
            )

    def check_units(self, q_deg: Sequence[Sequence[float] | None]) -> None:
        """InputError naming the first row where prev_q1..prev_qN look like radians beside q1..qN
        in degrees (looks_like_radians), or q1..qN beside prev_q in degrees; q_deg: each pose's
        joints, None where a pose gives none (a target without a starting guess)."""
        given = sorted((k, row, v) for k, (row, v) in self.by_pose.items() if v is not None)
        both = [(row, v, q_deg[k]) for k, row, v in given if q_deg[k] is not None]
        if not both:
            return
        prev = np.array([v for _, v, _ in both])
        q = np.array([w for _, _, w in both])
        n = self.robot.n_joints
        few = len(both) < PREV_MIN_POSES
        for small, big, name, other in ((prev, q, "prev_q", "q"), (q, prev, "q", "prev_q")):
            if few and few_look_like_radians(small, big, self.robot):
                # the pose and joint that show it best: the degrees' largest joint
                i, jd = (int(v) for v in np.unravel_index(int(np.argmax(np.abs(big))), big.shape))
                far, near = (np.linalg.norm(big[i] - s) for s in (small[i], np.rad2deg(small[i])))
                why = (
                    f"they lie within the joint limits read as radians, and read so the pose lies "
                    f"{near:.3g} deg from {other}1..{other}{n}, read as degrees {far:.3g} deg, "
                    "where an arm comes from a pose near the one it goes to"
                )
                self._refuse(both[i][0], small[i], big[i], jd, (name, other), why)
            if few or not looks_like_radians(small, big, self.robot):
                continue
            j = int(np.argmax(np.ptp(big, axis=0)))  # the joint that shows it best
            # a row that shows it: the degrees' joint beyond a turn in radians, the other off 0
            # (the first pose's prev_q is often home)
            shows = [i for i in range(len(both)) if abs(big[i, j]) > 2 * np.pi]
            at = next((i for i in shows if np.abs(small[i]).max() > LIMIT_TOL_DEG), shows[0])
            why = (
                f"over the {len(both)} poses that give both they lie within the joint limits "
                f"read as radians and spread {spread_ratio(small, big):.3g} times as much as "
                f"{other}1..{other}{n}, where the joints an arm comes from spread like its poses"
            )
            self._refuse(both[at][0], small[at], big[at], j, (name, other), why)

    def _refuse(self, row: Row, small, big, j: int, names: tuple[str, str], why: str) -> None:
        """InputError at the row and joint j (0-based) that show names[0] in radians beside
        names[1] in degrees (small, big: that pose's), and why they look so."""
        name, other = names
        n = self.robot.n_joints
        raise self.table.error(
            row,
            f"{name}{j + 1}",
            f"{small[j]:.6g} while {other}{j + 1} is {big[j]:.6g}: {name}1..{name}{n} look like "
            f"radians ({why}); give them in degrees",
        )

    def rad(self, m: int) -> np.ndarray | None:
        """(m, n) rad, NaN rows where a pose gives none; None without the columns."""
        if not self.have:
            return None
        out = np.full((m, len(self.have)), np.nan)
        for k, (_, v) in self.by_pose.items():
            if v is not None:
                out[k] = np.deg2rad(v)
        return out


class _Poses:
    """Collects poses in order of first appearance, checking joint limits and agreement."""

    def __init__(self, table: Table, robot: Robot):
        self.table, self.robot = table, robot
        self.columns = joint_columns(robot)
        self.ids: list[str] = []
        self.index: dict[str, int] = {}
        self.first: list[Row] = []
        self.q_deg: list[list[float]] = []

    def add(self, row: Row) -> tuple[int, bool]:
        """Index of this row's pose, and whether the row is the pose's first."""
        t = self.table
        pid = t.text(row, "pose")
        q = [joint_deg(t, row, i, name, self.robot) for i, name in enumerate(self.columns)]
        k = self.index.get(pid)
        if k is None:
            self.index[pid] = len(self.ids)
            self.ids.append(pid)
            self.first.append(row)
            self.q_deg.append(q)
            return len(self.ids) - 1, True
        first = self.first[k]
        for name, a, b in zip(self.columns, self.q_deg[k], q):
            if abs(a - b) > SAME_POSE_TOL_DEG:
                raise t.error(
                    row,
                    name,
                    f"{t.raw(row, name)} differs from {t.raw(first, name)} "
                    f"on line {first.line}, an earlier row of pose {pid!r}",
                )
        return k, False

    def q_rad(self) -> np.ndarray:
        return np.deg2rad(np.array(self.q_deg, dtype=float).reshape(len(self.ids), -1))


def read_campaign(path, robot: Robot, targets: Collection[str] | None = None) -> Measurements:
    """Read a `meas.csv` campaign (spec section 1) for this robot, its SMRs among `targets` when
    given (the cell's); InputError on any bad input.
    Column-wise at numpy's speed; row by row when that declines, to name the first bad line."""
    text = read_text(path)
    fast = read_campaign_columns(
        text, robot, MEASURED, EXTRAS, BOUNDS, LIMIT_TOL_DEG, SAME_POSE_TOL_DEG
    )
    if fast is not None and (targets is None or set(fast.target_names) <= set(targets)):
        return fast
    return read_campaign_rows(path, robot, text, targets)


def _unknown_target(target: str, targets: Collection[str]) -> str:
    """Why a target name the cell lacks is refused; a name that differs only in case says so."""
    alike = [n for n in targets if n.lower() == target.lower()]
    hint = f"; names are case-sensitive: {alike[0]!r}?" if alike else ""
    return f"target {target!r} is not among the cell's targets ({', '.join(targets)}){hint}"


def read_campaign_rows(
    path, robot: Robot, text: str | None = None, targets: Collection[str] | None = None
) -> Measurements:
    """read_campaign a row at a time: each row checked in turn, the first bad one named."""
    t = Table.read(path) if text is None else Table(path, text)
    t.require(["pose", *joint_columns(robot), "target", *MEASURED])
    extras = t.optional(list(EXTRAS))
    prev = PrevJoints(t, robot, prev_header(t, robot))
    t.require_rows()
    poses = _Poses(t, robot)
    seen: dict[tuple[str, str], Row] = {}
    names: set[str] = set()
    readings = []  # (pose index, target, xyz, extras)
    for row in t.rows:
        k, _ = poses.add(row)
        prev.add(row, k, poses.ids[k])
        target = t.text(row, "target")
        if not TARGET_NAME.fullmatch(target):
            raise t.error(
                row,
                "target",
                f"{target!r} is not a target name (a letter, then up "
                "to 15 letters, digits or '_', as in cell.json)",
            )
        if targets is not None and target not in targets:
            raise t.error(row, "target", _unknown_target(target, targets))
        names.add(target)
        if len(names) > SMRS_MAX:
            # The readings become a (poses, targets) table: bounded before it is built.
            raise t.error(
                row, "target", f"{target!r} is target {len(names)}; a cell has at most {SMRS_MAX}"
            )
        key = (poses.ids[k], target)
        if key in seen:
            raise t.error(
                row,
                "target",
                f"target {target!r} of pose {key[0]!r} is already on line {seen[key].line}",
            )
        seen[key] = row
        point = [t.number(row, c, None, *BOUNDS[c]) for c in MEASURED]
        # A blank time or temperature means "not recorded" (NaN), unlike a blank coordinate.
        more = [t.number(row, c, np.nan, *BOUNDS[c]) for c in extras]
        readings.append((k, target, point, more))
    prev.check_units(poses.q_deg)

    order = tuple(sorted(names))
    col = {n: j for j, n in enumerate(order)}
    m, K = len(poses.ids), len(order)
    xyz = np.full((m, K, 3), np.nan)
    extra = {c: np.full((m, K), np.nan) for c in extras}
    for k, target, p, more in readings:
        xyz[k, col[target]] = p
        for c, v in zip(extras, more):
            extra[c][k, col[target]] = v
    return Measurements(
        list(poses.ids),
        poses.q_rad(),
        order,
        xyz,
        extra.get("time_s"),
        extra.get("temp_c"),
        prev.rad(m),
    )


def read_poses(path, robot: Robot):
    """Read `poses.csv` (or a `meas.csv`, measured columns ignored) -> (ids, q rad, time_s,
    temp_c, prev_q rad).

    time_s and temp_c are (m,) arrays, or None when the column is absent; for a `meas.csv`
    each pose's is its first row's that is given (NaN where no row gives one). prev_q is (m, n), NaN rows where a pose gives
    none, or None without the columns. Column-wise first, as read_campaign.
    """
    text = read_text(path)
    fast = read_poses_columns(text, robot, EXTRAS, BOUNDS, LIMIT_TOL_DEG, SAME_POSE_TOL_DEG)
    return fast if fast is not None else read_poses_rows(path, robot, text)


def read_poses_rows(path, robot: Robot, text: str | None = None):
    """read_poses a row at a time."""
    t = Table.read(path) if text is None else Table(path, text)
    t.require(["pose", *joint_columns(robot)])
    extras = t.optional(list(EXTRAS))
    per_target = bool(t.optional(["target"]))
    prev = PrevJoints(t, robot, prev_header(t, robot))
    t.require_rows()
    poses = _Poses(t, robot)
    values: dict[str, list[float]] = {c: [] for c in extras}
    for row in t.rows:
        k, new = poses.add(row)
        prev.add(row, k, poses.ids[k])
        if not new and not per_target:
            first = poses.first[k]
            raise t.error(row, "pose", f"pose {poses.ids[k]!r} is already on line {first.line}")
        for c in extras:  # each pose's first value given (a reading's may be blank)
            if new:
                values[c].append(t.number(row, c, np.nan, *BOUNDS[c]))
            elif np.isnan(values[c][k]):
                values[c][k] = t.number(row, c, np.nan, *BOUNDS[c])
    prev.check_units(poses.q_deg)
    arrays = {c: np.array(v, dtype=float) for c, v in values.items()}
    ids = list(poses.ids)
    return ids, poses.q_rad(), arrays.get("time_s"), arrays.get("temp_c"), prev.rad(len(ids))


def _csv_text(header: list[str], rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def _fmt(value: float, spec: str) -> str:
    # NaN only occurs in the optional columns, where a blank field means "not recorded".
    return format(value, spec) if np.isfinite(value) else ""


def write_campaign(path, meas: Measurements) -> None:
    """Write a campaign as `meas.csv`, one row per present reading, atomically."""
    m, K = meas.xyz.shape[:2]
    q = np.asarray(meas.q, dtype=float)
    if q.ndim != 2 or q.shape[0] != m or len(meas.pose_ids) != m or len(meas.target_names) != K:
        raise ValueError("inconsistent Measurements: pose ids, q, target names and xyz disagree")
    if not np.all(np.isfinite(q)):
        raise ValueError("joint readings must be finite")
    if len(set(map(str, meas.pose_ids))) != m:
        raise ValueError("pose ids must be unique")
    extras = [
        (c, a) for c, a in (("time_s", meas.time_s), ("temp_c", meas.temp_c)) if a is not None
    ]
    prev = None if meas.prev_q is None else np.rad2deg(np.asarray(meas.prev_q, dtype=float))
    header = [
        "pose",
        *[f"q{i}" for i in range(1, q.shape[1] + 1)],
        "target",
        *MEASURED,
        *[c for c, _ in extras],
        *([f"prev_q{i}" for i in range(1, q.shape[1] + 1)] if prev is not None else []),
    ]
    q_deg = np.rad2deg(q)
    mask = meas.mask
    rows = []
    for i, pid in enumerate(meas.pose_ids):
        joints = [f"{v:.9f}" for v in q_deg[i]]
        for k, name in enumerate(meas.target_names):
            if mask[i, k]:
                rows.append(
                    [
                        str(pid),
                        *joints,
                        name,
                        *[f"{v:.6f}" for v in meas.xyz[i, k]],
                        *[_fmt(a[i, k], ".6f") for _, a in extras],
                        *([_fmt(v, ".9f") for v in prev[i]] if prev is not None else []),
                    ]
                )
    atomic_write_text(path, _csv_text(header, rows))


def write_predictions(path, pose_ids, target_names, xyz) -> None:
    """Write `pred.csv`: `pose,target,x,y,z`, one row per (pose, target), atomically."""
    xyz = np.asarray(xyz, dtype=float)
    if xyz.shape != (len(pose_ids), len(target_names), 3):
        raise ValueError(
            f"xyz has shape {xyz.shape}, expected ({len(pose_ids)}, {len(target_names)}, 3)"
        )
    if not np.all(np.isfinite(xyz)):
        raise ValueError("predictions must be finite")
    rows = [
        [str(pid), name, *[f"{v:.6f}" for v in xyz[i, k]]]
        for i, pid in enumerate(pose_ids)
        for k, name in enumerate(target_names)
    ]
    atomic_write_text(path, _csv_text(["pose", "target", *MEASURED], rows))


__all__ = ["joint_columns", "read_campaign", "read_poses", "write_campaign", "write_predictions"]


def write_poses(path, pose_ids, q_rad) -> None:
    """Write `poses.csv`: `pose,q1..qN` (degrees), one row a pose, atomically."""
    q = np.asarray(q_rad, dtype=float)
    if q.ndim != 2 or len(pose_ids) != len(q) or not np.all(np.isfinite(q)):
        raise ValueError("poses must be finite (m, N) joints, one id a pose")
    rows = [[str(p), *[f"{v:.9f}" for v in np.rad2deg(row)]] for p, row in zip(pose_ids, q)]
    atomic_write_text(path, _csv_text(["pose", *[f"q{i}" for i in range(1, q.shape[1] + 1)]], rows))
