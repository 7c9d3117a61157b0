"""The identified kinematic parameters as a table (CSV): per joint in the robot's convention,
then the base frame and the SMR positions, nominal beside calibrated."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass

import numpy as np

from robocal.server.formats.csv_table import Table
from robocal.server.formats.errors import InputError
from robocal.server.formats.model_json import ModelFile
from robocal.solver.kinematics import rot, translation
from robocal.solver.robot import Robot

from .frames import rpy_from_matrix

HEADER = [
    "parameter",
    "joint",
    "convention",
    "unit",
    "nominal",
    "calibrated",
    "difference",
    "standard_error",
    "status",
]
# the paper's table order within a joint (a DH table's columns), beta last
JOINT_ORDER = ("a", "alpha", "d", "theta", "beta")
ANGLES = ("alpha", "theta", "beta")
BASE = ("base_x", "base_y", "base_z", "base_rz", "base_ry", "base_rx")
DIGITS = ".9f"  # 1e-9 mm and deg: reading the table back moves a prediction by far less than 1 nm


@dataclass(frozen=True)
class Entry:
    """One row: a parameter in edge units (mm, degrees)."""

    name: str
    joint: int | None
    unit: str
    calibrated: float
    nominal: float | None = None
    standard_error: float | None = None
    status: str = ""


def base_entries(base: np.ndarray) -> list[tuple[str, str, float]]:
    """The base frame as x, y, z (mm, tracker frame) and rz, ry, rx (deg) with
    base = Trans(x, y, z) Rz(rz) Ry(ry) Rx(rx), the solver's base order."""
    rx, ry, rz = np.rad2deg(rpy_from_matrix(base[:3, :3]))
    x, y, z = base[:3, 3]
    values = (x, y, z, rz, ry, rx)
    return [(n, "mm" if i < 3 else "deg", float(v)) for i, (n, v) in enumerate(zip(BASE, values))]


def base_from_entries(values: dict[str, float]) -> np.ndarray:
    """The 4x4 base of base_entries' six values."""
    x, y, z, rz, ry, rx = (values[n] for n in BASE)
    return (
        translation(x, y, z)
        @ rot(2, np.deg2rad(rz))
        @ rot(1, np.deg2rad(ry))
        @ rot(0, np.deg2rad(rx))
    )


def entries(model: ModelFile) -> list[Entry]:
    """Every row of the table, joints first (a, alpha, d, theta, beta), then base and SMRs.

    A model with an `identified` block (written since the table was) gives the base's standard
    errors in these tracker-frame coordinates and the SMRs' nominal positions."""
    unc = (model.uncertainty.standard_errors if model.uncertainty else None) or {}
    known = {r.parameter: r for r in model.identified.rows} if model.identified else {}
    fixed = (model.fit.fixed_parameters if model.fit else None) or {}
    has_fit = model.fit is not None and bool(model.fit.to_json())

    shrunk = {s.parameter: s for s in model.identified.shrunk} if model.identified else {}

    def status(name):
        if name in fixed:
            return f"held fixed: {fixed[name]}"
        if name in shrunk:
            s = shrunk[name]
            return f"shrunk toward nominal ({s.data_share:.0%} from the data): {s.why}"
        return "identified" if has_fit else ""

    cal = dict(zip(model.robot.param_names(), model.robot.param_vector()))
    nom = {}
    if model.nominal is not None:  # by name: a nominal without beta on a joint has none there
        nom = dict(zip(model.nominal.param_names(), model.nominal.param_vector()))
    rows = []
    for i, par in enumerate(model.robot.parallel, start=1):
        for p in JOINT_ORDER:
            if p == "beta" and not par:
                continue
            name = f"{p}{i}"
            scale = 180.0 / np.pi if p in ANGLES else 1.0
            rows.append(
                Entry(
                    name,
                    i,
                    "deg" if p in ANGLES else "mm",
                    float(cal[name] * scale),
                    float(nom[name] * scale) if name in nom else None,
                    unc.get(name),
                    status(name),
                )
            )
    # the uncertainty block's standard errors of the base are along and about the calibrated
    # base's own axes, not of these tracker-frame coordinates and angles: taken from the
    # identified block (propagated to them), else left blank
    rows += [
        Entry(
            n,
            None,
            u,
            v,
            known[n].nominal if n in known else None,
            known[n].standard_error if n in known else None,
            status(n),
        )
        for n, u, v in base_entries(model.base)
    ]
    for t, xyz in model.targets.items():
        for c, v in zip("xyz", xyz):
            name = f"{t}_{c}"
            nominal = known[name].nominal if name in known else None
            rows.append(Entry(name, None, "mm", float(v), nominal, unc.get(name), status(name)))
    return rows


def _fmt(v: float | None, spec: str = DIGITS) -> str:
    return "" if v is None else format(v + 0.0, spec)


def params_text(model: ModelFile) -> str:
    """The table as CSV with a header row."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(HEADER)
    conv = model.robot.convention
    for e in entries(model):
        diff = None if e.nominal is None else e.calibrated - e.nominal
        w.writerow(
            [
                e.name,
                "" if e.joint is None else e.joint,
                conv if e.joint is not None else "",
                e.unit,
                _fmt(e.nominal),
                _fmt(e.calibrated),
                _fmt(diff),
                _fmt(e.standard_error, ".3g"),
                e.status,
            ]
        )
    return buf.getvalue()


def read_params(path) -> dict[str, float]:
    """The calibrated value of each parameter of a params table (mm, deg), by name."""
    t = Table.read(path)
    t.require(["parameter", "calibrated"])
    t.require_rows()
    values: dict[str, float] = {}
    lines: dict[str, int] = {}
    for row in t.rows:
        name = t.text(row, "parameter")
        if name in values:
            raise t.error(row, "parameter", f"{name!r} is already on line {lines[name]}")
        values[name], lines[name] = t.number(row, "calibrated"), row.line
    return values


def apply_params(
    path, values: dict[str, float], robot: Robot, target_names
) -> tuple[Robot, np.ndarray, dict[str, np.ndarray]]:
    """The robot (with this one's structure and limits), base and SMR positions that a table's
    values describe; InputError naming the first parameter the table lacks."""
    names = robot.param_names() + list(BASE) + [f"{t}_{c}" for t in target_names for c in "xyz"]
    missing = [n for n in names if n not in values]
    if missing:
        raise InputError(path, None, None, f"parameter {missing[0]!r} is missing")
    geo = [
        np.deg2rad(values[n]) if n.rstrip("0123456789") in ANGLES else values[n]
        for n in robot.param_names()
    ]
    targets = {t: np.array([values[f"{t}_{c}"] for c in "xyz"]) for t in target_names}
    return robot.with_params(np.array(geo)), base_from_entries(values), targets
