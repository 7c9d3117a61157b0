"""The cell description (`cell.json`, spec section 2) and robots as JSON objects."""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass, field

import numpy as np
from robocal.solver.robot import BUILTIN, IRB2600, Joint, Robot, detect_parallel

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
DEVICE_KEYS = ("tracker", "controller")
TRACKER_ADDRESS_KEYS = ("host", "port", "timeout_s")
CONTROLLER_ADDRESS_KEYS = ("url", "baudrate", "timeout_s")
# pyserial URL schemes that reach a controller over the network; other strings are serial ports
NETWORK_SCHEMES = ("socket", "rfc2217")
HOST_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9.-]{0,252}")
SERIAL_PORT = re.compile(r"/dev/[A-Za-z0-9._/-]+|COM[0-9]{1,3}|\\\\\.\\COM[0-9]{1,3}")
DEFAULT_TIMEOUT_S, DEFAULT_BAUDRATE = 5.0, 9600


@dataclass(frozen=True)
class Devices:
    """Where a real cell's devices answer: the tracker over TCP, the controller over pyserial."""

    tracker_host: str
    tracker_port: int
    controller_url: str  # socket://host:port, rfc2217://host:port or a serial port (/dev/ttyUSB0)
    tracker_timeout_s: float = DEFAULT_TIMEOUT_S
    controller_timeout_s: float = DEFAULT_TIMEOUT_S
    baudrate: int = DEFAULT_BAUDRATE  # serial ports only

    def tracker_address(self) -> str:
        return f"{self.tracker_host}:{self.tracker_port}"


@dataclass
class Cell:
    """The robot, its SMR targets (mm, flange frame) and what is known of the tracker setup."""

    robot: Robot
    targets: dict[str, np.ndarray]
    base: np.ndarray | None = None  # 4x4 base-in-tracker guess, mm
    tracker: dict = field(default_factory=lambda: dict(TRACKER_DEFAULTS))
    payload_kg: float | None = None
    devices: Devices | None = None  # None: the simulated cell

    @property
    def simulated(self) -> bool:
        return self.devices is None


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
    devices = None if root.get("devices") is None else _devices(doc, root["devices"])
    if devices is not None and base is None:
        # Planning and the tracker's first aims need the base: a search covers 10 to 50 mm
        # around each predicted SMR, not the metres between the tracker and an unknown base.
        raise doc.error(
            ("devices",),
            "a cell with real devices needs a `base` guess (4x4, the "
            "robot base in the tracker frame, to within about 10 mm)",
            key=True,
        )
    if devices is not None:
        _within_builtin(doc, root["robot"], robot)
    return Cell(robot, targets, base, tracker, payload, devices)


def _builtin_named(name: str) -> Robot | None:
    """The built-in robot an inline robot's name designates ("IRB 2600", "irb-2600"), if any."""
    return BUILTIN.get(re.sub(r"[^a-z0-9]", "", name.lower()))


def _within_builtin(doc: JsonDoc, value, robot: Robot) -> None:
    """A real arm is never driven beyond its built-in model's limits, whatever the upload says."""
    model = _builtin_named(robot.name) if isinstance(value, dict) else None
    if model is None:
        return
    if robot.n_joints != model.n_joints:
        raise doc.error(
            ("robot", "joints"),
            f"names the built-in {model.name}, which has "
            f"{model.n_joints} joints, not {robot.n_joints}",
        )
    tol = 1e-4  # degrees: the controller protocol's resolution
    for i, (mine, theirs) in enumerate(zip(robot.joints, model.joints)):
        lo, hi = _deg(mine.limits[0]), _deg(mine.limits[1])
        blo, bhi = _deg(theirs.limits[0]), _deg(theirs.limits[1])
        if lo < blo - tol or hi > bhi + tol:
            raise doc.error(
                ("robot", "joints", i, "limits"),
                f"[{lo:g}, {hi:g}] deg exceeds the built-in {model.name}'s "
                f"[{blo:g}, {bhi:g}] for joint {i + 1}; a cell with real devices "
                "may only narrow a built-in robot's limits",
            )


def _robot(doc: JsonDoc, value) -> Robot:
    if isinstance(value, str):
        robot = BUILTIN.get(value.strip().lower())
        if robot is None:
            raise doc.error(
                ("robot",),
                f"unknown robot {value!r}; built-in robots: "
                f"{', '.join(sorted(BUILTIN))}, or give an inline robot object",
            )
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
            raise doc.error(
                (*at, name),
                f"target name {name!r} must be a letter followed by up to "
                "15 letters, digits or '_'",
                key=True,
            )
        doc.array(xyz, (*at, name), 3)
        targets[name] = np.array([doc.coordinate(v, (*at, name, i)) for i, v in enumerate(xyz)])
    return targets


def _base(doc: JsonDoc, value) -> np.ndarray:
    at = ("base",)
    doc.array(value, at, 4)
    rows = [doc.array(r, (*at, i), 4) for i, r in enumerate(value)]
    T = np.array(
        [[doc.coordinate(v, (*at, i, j)) for j, v in enumerate(r)] for i, r in enumerate(rows)]
    )
    if np.max(np.abs(T[3] - [0, 0, 0, 1])) > 1e-9:
        raise doc.error((*at, 3), "the last row of a homogeneous transform must be [0, 0, 0, 1]")
    R = T[:3, :3]
    err = np.max(np.abs(R.T @ R - np.eye(3)))
    if err > ORTHONORMAL_TOL:
        raise doc.error(
            at,
            f"rotation part is not orthonormal (max |R'R - I| = {err:.3g}, "
            f"tolerance {ORTHONORMAL_TOL:g})",
        )
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


def _devices(doc: JsonDoc, value) -> Devices:
    doc.object(value, ("devices",), DEVICE_KEYS)
    at = ("devices", "tracker")
    tracker = doc.object(doc.require(value, "tracker", ("devices",)), at, TRACKER_ADDRESS_KEYS)
    host = doc.string(doc.require(tracker, "host", at), (*at, "host")).strip()
    if not _is_host(host):
        raise doc.error((*at, "host"), f"{host!r} is not a host name or IP address")
    host = host[1:-1] if host.startswith("[") else host  # a socket wants IPv6 bare
    port = doc.integer(doc.require(tracker, "port", at), (*at, "port"), 1, 65535)
    t_timeout = _timeout(doc, tracker, at)
    at = ("devices", "controller")
    controller = doc.object(
        doc.require(value, "controller", ("devices",)), at, CONTROLLER_ADDRESS_KEYS
    )
    url = _controller_url(doc, doc.require(controller, "url", at), (*at, "url"))
    baudrate = DEFAULT_BAUDRATE
    if "baudrate" in controller:
        baudrate = doc.integer(controller["baudrate"], (*at, "baudrate"), 50, 4_000_000)
    return Devices(host, port, url, t_timeout, _timeout(doc, controller, at), baudrate)


def _controller_url(doc: JsonDoc, value, at: tuple) -> str:
    url = doc.string(value, at).strip()
    scheme, sep, rest = url.partition("://")
    if not sep:
        if not SERIAL_PORT.fullmatch(url):
            raise doc.error(
                at,
                f"{url!r} is neither socket://host:port nor a serial port such "
                "as /dev/ttyUSB0 or COM3",
            )
        return url
    if scheme not in NETWORK_SCHEMES:
        raise doc.error(
            at,
            f"scheme {scheme!r} is not one of "
            f"{', '.join(s + '://' for s in NETWORK_SCHEMES)} (or a serial port)",
        )
    host, colon, port = rest.split("?", 1)[0].rpartition(":")
    if not colon or not _is_host(host) or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise doc.error(at, f"{url!r}: expected {scheme}://host:port with a port in 1..65535")
    return url


def _is_host(host: str) -> bool:
    """A host name or an IP address (IPv6 in brackets or bare)."""
    try:
        ipaddress.ip_address(host[1:-1] if host.startswith("[") and host.endswith("]") else host)
        return True
    except ValueError:
        return bool(HOST_NAME.fullmatch(host))


def _timeout(doc: JsonDoc, obj: dict, at: tuple) -> float:
    if "timeout_s" not in obj:
        return DEFAULT_TIMEOUT_S
    t = doc.number(obj["timeout_s"], (*at, "timeout_s"))
    if not 0.0 < t <= 600.0:
        raise doc.error((*at, "timeout_s"), f"{t:g} s must be in (0, 600]")
    return t


def devices_to_json(d: Devices) -> dict:
    """The `devices` object of a cell.json (every value spelled out)."""
    return {
        "tracker": {
            "host": d.tracker_host,
            "port": d.tracker_port,
            "timeout_s": d.tracker_timeout_s,
        },
        "controller": {
            "url": d.controller_url,
            "baudrate": d.baudrate,
            "timeout_s": d.controller_timeout_s,
        },
    }


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
        a, d = (doc.coordinate(doc.require(row, k, jat), (*jat, k)) for k in ("a", "d"))
        theta, alpha = (doc.angle(doc.require(row, k, jat), (*jat, k)) for k in ("theta", "alpha"))
        lo, hi = _limits(doc, row.get("limits"), (*jat, "limits"))
        beta = doc.angle(row["beta"], (*jat, "beta")) if "beta" in row else 0.0
        joints.append(
            Joint(
                a=a,
                d=d,
                theta=_rad(theta),
                alpha=_rad(alpha),
                limits=(_rad(lo), _rad(hi)),
                beta=_rad(beta),
            )
        )
        has_beta.append("beta" in row)
    detected = detect_parallel(convention, joints)
    for i, (det, beta) in enumerate(zip(detected, has_beta)):
        # Kinematics only uses beta on parallel axes; elsewhere it would be a silently dead value.
        if beta and not det:
            raise doc.error(
                (*at, "joints", i, "beta"),
                f"joint {i + 1} has no parallel neighbour axis, so beta does not apply",
                key=True,
            )
    return Robot(name, convention, tuple(joints), detected)


def _limits(doc: JsonDoc, value, at: tuple) -> tuple[float, float]:
    if value is None:
        return DEFAULT_LIMITS_DEG
    doc.array(value, at, 2)
    lo, hi = (doc.angle(v, (*at, i)) for i, v in enumerate(value))
    if not lo < hi:
        raise doc.error(at, f"lower limit {lo:g} must be below upper limit {hi:g}")
    return lo, hi


def robot_to_json(robot: Robot) -> dict:
    """The inline JSON object of a robot (degrees, mm), with beta on its parallel joints."""
    joints = []
    for j, par in zip(robot.joints, robot.parallel):
        row = {
            "a": float(j.a),
            "d": float(j.d),
            "theta": _deg(j.theta),
            "alpha": _deg(j.alpha),
            "limits": [_deg(j.limits[0]), _deg(j.limits[1])],
        }
        if par:
            row["beta"] = _deg(j.beta)
        joints.append(row)
    return {"name": robot.name, "convention": robot.convention, "joints": joints}


def cell_to_json(cell: Cell) -> dict:
    """The JSON object of a cell; a built-in robot is written by name."""
    builtin = BUILTIN.get(cell.robot.name)
    out = {
        "robot": cell.robot.name if builtin == cell.robot else robot_to_json(cell.robot),
        "targets": {k: [float(x) for x in v] for k, v in cell.targets.items()},
    }
    if cell.base is not None:
        out["base"] = np.asarray(cell.base, dtype=float).tolist()
    out["tracker"] = {
        k: (float(v) if isinstance(v, (int, float, np.floating)) else v)
        for k, v in cell.tracker.items()
    }
    if cell.payload_kg is not None:
        out["payload_kg"] = float(cell.payload_kg)
    if cell.devices is not None:
        out["devices"] = devices_to_json(cell.devices)
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
