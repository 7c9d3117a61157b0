"""The cell description (`cell.json`, spec section 2) and robots as JSON objects."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from solver.robot import BUILTIN, IRB2600, Joint, Robot, detect_parallel

from .files import read_text
from .json_doc import JsonDoc

JOINT_KEYS = ("a", "d", "theta", "alpha", "limits", "beta")
ROBOT_KEYS = ("name", "convention", "joints")
DEFAULT_LIMITS_DEG = (-180.0, 180.0)
TRACKER_DEFAULTS = {"mpe_um": 10.0, "mpe_um_per_m": 2.5}
# Letters like the spec's A, B, C, or short identifiers such as SMR1: they become CSV values
# and parameter names (A_x), so no spaces or punctuation.
TARGET_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,15}")
ORTHONORMAL_TOL = 1e-6


@dataclass
class Cell:
    """The robot, its SMR targets (mm, flange frame) and what is known of the tracker setup."""

    robot: Robot
    targets: dict[str, np.ndarray]
    base: np.ndarray | None = None  # 4x4 base-in-tracker guess, mm
    tracker: dict = field(default_factory=lambda: dict(TRACKER_DEFAULTS))
    payload_kg: float | None = None


def default_cell() -> Cell:
    """The spec's example cell: the built-in IRB 2600 with targets A, B, C."""
    targets = {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]}
    return Cell(IRB2600, {k: np.array(v) for k, v in targets.items()})


def read_cell(path) -> Cell:
    """Read and validate a `cell.json` file; InputError naming line and column on bad input."""
    return parse_cell(read_text(path), path)


def parse_cell(text: str, path="<cell>") -> Cell:
    """Parse and validate the text of a `cell.json`."""
    doc, root = JsonDoc.parse(path, text)
    doc.object(root, ())
    robot = _robot(doc, doc.require(root, "robot", ()))
    targets = _targets(doc, doc.require(root, "targets", ()))
    base = None if root.get("base") is None else _base(doc, root["base"])
    tracker = _tracker(doc, root.get("tracker"))
    payload = root.get("payload_kg")
    if payload is not None:
        payload = doc.number(payload, ("payload_kg",), minimum=0.0)
    return Cell(robot, targets, base, tracker, payload)


def _robot(doc: JsonDoc, value) -> Robot:
    if isinstance(value, str):
        robot = BUILTIN.get(value.strip().lower())
        if robot is None:
            raise doc.error(("robot",), f"unknown robot {value!r}; built-in robots: "
                                        f"{', '.join(sorted(BUILTIN))}, or give an inline robot object")
        return robot
    return robot_from_json(value, doc, ("robot",))


def _targets(doc: JsonDoc, value) -> dict[str, np.ndarray]:
    at = ("targets",)
    doc.object(value, at)
    if not value:
        raise doc.error(at, "at least one target is needed")
    targets = {}
    for name, xyz in value.items():
        if not TARGET_NAME.fullmatch(name):
            raise doc.error((*at, name), f"target name {name!r} must be a letter followed by up to "
                                         "15 letters, digits or '_'", key=True)
        doc.array(xyz, (*at, name), 3)
        targets[name] = np.array([doc.number(v, (*at, name, i)) for i, v in enumerate(xyz)])
    return targets


def _base(doc: JsonDoc, value) -> np.ndarray:
    at = ("base",)
    doc.array(value, at, 4)
    rows = [doc.array(r, (*at, i), 4) for i, r in enumerate(value)]
    T = np.array([[doc.number(v, (*at, i, j)) for j, v in enumerate(r)] for i, r in enumerate(rows)])
    if np.max(np.abs(T[3] - [0, 0, 0, 1])) > 1e-9:
        raise doc.error((*at, 3), "the last row of a homogeneous transform must be [0, 0, 0, 1]")
    R = T[:3, :3]
    err = np.max(np.abs(R.T @ R - np.eye(3)))
    if err > ORTHONORMAL_TOL:
        raise doc.error(at, f"rotation part is not orthonormal (max |R'R - I| = {err:.3g}, "
                            f"tolerance {ORTHONORMAL_TOL:g})")
    if np.linalg.det(R) < 0:
        raise doc.error(at, "rotation part is a reflection (determinant -1), not a rotation")
    return T


def _tracker(doc: JsonDoc, value) -> dict:
    tracker = dict(TRACKER_DEFAULTS)
    if value is None:
        return tracker
    doc.object(value, ("tracker",))
    tracker.update(value)
    for key in TRACKER_DEFAULTS:
        tracker[key] = doc.number(tracker[key], ("tracker", key), minimum=0.0)
    return tracker


def robot_from_json(obj, doc: JsonDoc | None = None, at: tuple = ()) -> Robot:
    """A robot from its inline JSON object (degrees, mm); errors located through `doc` if given."""
    doc = doc or JsonDoc("<robot>")
    doc.object(obj, at, ROBOT_KEYS)
    name = doc.string(obj.get("name", "custom"), (*at, "name")).strip()
    convention = doc.require(obj, "convention", at)
    if convention not in ("dh", "mdh"):
        raise doc.error((*at, "convention"), f"must be 'dh' or 'mdh', not {convention!r}")
    rows = doc.array(doc.require(obj, "joints", at), (*at, "joints"))
    if not rows:
        raise doc.error((*at, "joints"), "at least one joint is needed")
    joints, has_beta = [], []
    for i, row in enumerate(rows):
        jat = (*at, "joints", i)
        doc.object(row, jat, JOINT_KEYS)
        a, d, theta, alpha = (doc.number(doc.require(row, k, jat), (*jat, k))
                              for k in ("a", "d", "theta", "alpha"))
        lo, hi = _limits(doc, row.get("limits"), (*jat, "limits"))
        beta = doc.number(row["beta"], (*jat, "beta")) if "beta" in row else 0.0
        joints.append(Joint(a=a, d=d, theta=_rad(theta), alpha=_rad(alpha),
                            limits=(_rad(lo), _rad(hi)), beta=_rad(beta)))
        has_beta.append("beta" in row)
    detected = detect_parallel(convention, joints)
    for i, (det, beta) in enumerate(zip(detected, has_beta)):
        # Kinematics only uses beta on parallel axes; elsewhere it would be a silently dead value.
        if beta and not det:
            raise doc.error((*at, "joints", i, "beta"), f"joint {i + 1} has no parallel neighbour "
                                                        "axis, so beta does not apply", key=True)
    return Robot(name, convention, tuple(joints), detected)


def _limits(doc: JsonDoc, value, at: tuple) -> tuple[float, float]:
    if value is None:
        return DEFAULT_LIMITS_DEG
    doc.array(value, at, 2)
    lo, hi = (doc.number(v, (*at, i)) for i, v in enumerate(value))
    if not lo < hi:
        raise doc.error(at, f"lower limit {lo:g} must be below upper limit {hi:g}")
    return lo, hi


def robot_to_json(robot: Robot) -> dict:
    """The inline JSON object of a robot (degrees, mm), with beta on its parallel joints."""
    joints = []
    for j, par in zip(robot.joints, robot.parallel):
        row = {"a": float(j.a), "d": float(j.d), "theta": _deg(j.theta), "alpha": _deg(j.alpha),
               "limits": [_deg(j.limits[0]), _deg(j.limits[1])]}
        if par:
            row["beta"] = _deg(j.beta)
        joints.append(row)
    return {"name": robot.name, "convention": robot.convention, "joints": joints}


def cell_to_json(cell: Cell) -> dict:
    """The JSON object of a cell; a built-in robot is written by name."""
    builtin = BUILTIN.get(cell.robot.name)
    out = {"robot": cell.robot.name if builtin == cell.robot else robot_to_json(cell.robot),
           "targets": {k: [float(x) for x in v] for k, v in cell.targets.items()}}
    if cell.base is not None:
        out["base"] = np.asarray(cell.base, dtype=float).tolist()
    out["tracker"] = {k: (float(v) if isinstance(v, (int, float, np.floating)) else v)
                      for k, v in cell.tracker.items()}
    if cell.payload_kg is not None:
        out["payload_kg"] = float(cell.payload_kg)
    return out


def _rad(deg: float) -> float:
    return float(np.deg2rad(deg))


def _deg(rad: float) -> float:
    """Degrees that convert back to this float: bit for bit when such a double exists (about 91%
    of values; deg2rad skips some doubles), else to the nearest one (1 ulp, ~1e-16 rad)."""
    rad = float(rad)
    d = float(np.rad2deg(rad))
    candidates = [d]
    up = down = d
    for _ in range(8):
        up, down = float(np.nextafter(up, np.inf)), float(np.nextafter(down, -np.inf))
        candidates += [up, down]
    exact = [c for c in candidates if _rad(c) == rad]
    if exact:
        # The shortest decimal keeps hand-entered values readable: 120.0, not 119.99999999999999.
        return min(exact, key=lambda c: (len(repr(c)), abs(c - d)))
    return min(candidates, key=lambda c: abs(_rad(c) - rad))
