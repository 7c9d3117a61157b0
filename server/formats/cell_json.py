"""The cell description (`cell.json`, spec section 2) and robots as JSON objects."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robocal.solver.robot import BUILTIN, IRB2600, Robot

from .cell_doc import TARGET_NAME, CellDoc, RobotDoc  # noqa: F401 (TARGET_NAME: for readers)
from .files import read_text
from .json_doc import JsonDoc

TRACKER_DEFAULTS = {"mpe_um": 10.0, "mpe_um_per_m": 2.5}
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
    tracker_spec_given: bool = False  # tracker holds the default spec unless the file gave one
    tolerance_mm: float | None = None  # the accuracy the application needs; None: not given
    # the arm's pose repeatability RP (ISO 9283) as its data sheet states it; None: not given
    repeatability_mm: float | None = None

    @property
    def simulated(self) -> bool:
        return self.devices is None

    def target_positions(self, names) -> np.ndarray:
        """(K, 3) the nominal positions (mm, flange frame) of the named SMRs, in that order."""
        return np.array([self.targets[t] for t in names], dtype=float)


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
    return cell_from_doc(doc.validate(CellDoc, root))


def cell_from_doc(c: CellDoc) -> Cell:
    """The cell a validated cell.json describes (numpy arrays, radians inside the robot)."""
    devices = None
    if c.devices is not None:
        t, k = c.devices.tracker, c.devices.controller
        host = t.host[1:-1] if t.host.startswith("[") else t.host  # a socket wants IPv6 bare
        devices = Devices(host, t.port, k.url, t.timeout_s, k.timeout_s, k.baudrate)
    return Cell(
        c.robot_model,
        {name: np.array(xyz, dtype=float) for name, xyz in c.targets.items()},
        None if c.base is None else np.array(c.base, dtype=float),
        # as JSON gives them (a due date a string): what the cell's JSON is written back from
        c.tracker.model_dump(mode="json", exclude_none=True),
        c.payload_kg,
        devices,
        bool({"mpe_um", "mpe_um_per_m"} & c.tracker.model_fields_set),
        c.tolerance_mm,
        c.repeatability_mm,
    )


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


def robot_from_json(obj, path="<robot>") -> Robot:
    """A robot from its inline JSON object (degrees, mm)."""
    return JsonDoc(path).validate(RobotDoc, obj).robot


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
    out: dict[str, Any] = {
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
    if cell.tolerance_mm is not None:
        out["tolerance_mm"] = float(cell.tolerance_mm)
    if cell.repeatability_mm is not None:
        out["repeatability_mm"] = float(cell.repeatability_mm)
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
