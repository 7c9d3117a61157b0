"""The shape of `cell.json` (spec section 2) as pydantic models, shared by the file and the API."""

from __future__ import annotations

import datetime as dt
import ipaddress
import re
from typing import Annotated, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    ConfigDict,
    Discriminator,
    Field,
    PrivateAttr,
    Tag,
    field_validator,
    model_validator,
)

from robocal.solver.robot import BUILTIN, Joint, Robot, detect_parallel

from .fields import (
    TARGET_NAME_PATTERN,
    Angle,
    Doc,
    Label,
    Link,
    Matrix4,
    NonNegative,
    Point,
    Whole,
    located,
)
from .limits import JOINTS_MAX, REACH_MIN_MM, SMRS_MAX

TARGET_NAME = re.compile(TARGET_NAME_PATTERN)
DEFAULT_LIMITS_DEG = (-180.0, 180.0)
ORTHONORMAL_TOL = 1e-6
# pyserial URL schemes that reach a controller over the network; other strings are serial ports
NETWORK_SCHEMES = ("socket", "rfc2217")
HOST_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9.-]{0,252}")
SERIAL_PORT = re.compile(r"/dev/[A-Za-z0-9._/-]+|COM[0-9]{1,3}|\\\\\.\\COM[0-9]{1,3}")
Timeout = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0.0, le=600.0)]


class JointDoc(Doc):
    """One row of the DH (or modified DH) table: mm and degrees."""

    a: Link
    d: Link
    theta: Angle = Field(description="zero offset added to the joint reading, degrees")
    alpha: Angle
    limits: Annotated[list[Angle], Field(min_length=2, max_length=2)] = list(DEFAULT_LIMITS_DEG)
    beta: Angle | None = Field(None, description="Hayati's beta, parallel axes only")

    @model_validator(mode="after")
    def _ordered(self):
        lo, hi = self.limits
        if not lo < hi:
            raise located(f"lower limit {lo:g} must be below upper limit {hi:g}", "limits")
        return self

    def joint(self) -> Joint:
        """The solver's joint (radians)."""
        return Joint(
            a=self.a,
            d=self.d,
            theta=_rad(self.theta),
            alpha=_rad(self.alpha),
            limits=(_rad(self.limits[0]), _rad(self.limits[1])),
            beta=_rad(self.beta or 0.0),
        )


class RobotDoc(Doc):
    """An inline robot: its convention and joint table."""

    name: Label = "custom"
    convention: Literal["dh", "mdh"] = Field(
        description="dh: Rz(theta) Tz(d) Tx(a) Rx(alpha); mdh: Rx(alpha) Tx(a) Rz(theta) Tz(d)"
    )
    joints: list[JointDoc] = Field(
        description=f"from the base; their links (sqrt(a^2 + d^2)) add up to at least "
        f"{REACH_MIN_MM:g} mm",
        json_schema_extra={"minItems": 1, "maxItems": JOINTS_MAX},
    )
    _robot: Robot = PrivateAttr()

    @model_validator(mode="after")
    def _build(self):
        if not self.joints:
            raise located("at least one joint is needed", "joints")
        if len(self.joints) > JOINTS_MAX:
            raise located(
                f"{len(self.joints)} joints; a serial arm has at most {JOINTS_MAX}", "joints"
            )
        reach = sum(float(np.hypot(j.a, j.d)) for j in self.joints)
        if reach < REACH_MIN_MM:
            # All zeros (or metres for mm) would plan no pose and fit nothing: refused here.
            raise located(
                f"the links add up to {reach:g} mm (the sum of sqrt(a^2 + d^2)); an arm's add "
                f"up to at least {REACH_MIN_MM:g} mm: give a and d in mm",
                "joints",
            )
        if all(max(abs(v) for v in j.limits) <= RADIANS_TURN for j in self.joints):
            # no arm turns every joint less than 13 degrees: a joint table in radians
            raise located(
                f"every joint's limits lie within +-{RADIANS_TURN:.2f}: they look like radians; "
                "give them in degrees",
                "joints",
                0,
                "limits",
                key=True,
            )
        joints = [j.joint() for j in self.joints]
        detected = detect_parallel(self.convention, joints)
        for i, (det, row) in enumerate(zip(detected, self.joints)):
            # Kinematics only uses beta on parallel axes; elsewhere it would be a dead value.
            if row.beta is not None and not det:
                raise located(
                    f"joint {i + 1} has no parallel neighbour axis, so beta does not apply",
                    "joints",
                    i,
                    "beta",
                    key=True,
                )
        self._robot = Robot(self.name.strip(), self.convention, tuple(joints), detected)
        return self

    @property
    def robot(self) -> Robot:
        return self._robot


def builtin_robot(name: str) -> Robot:
    robot = BUILTIN.get(name.strip().lower())
    if robot is None:
        raise located(
            f"unknown robot {name!r}; built-in robots: {', '.join(sorted(BUILTIN))}, "
            "or give an inline robot object"
        )
    return robot


def _any_case(name: str) -> str:
    return "".join(f"[{c.lower()}{c.upper()}]" if c.isalpha() else re.escape(c) for c in name)


BuiltinName = Annotated[
    str,
    Field(
        strict=True,
        description=f"a built-in robot: {', '.join(sorted(BUILTIN))}",
        # builtin_robot's rule (any case, blanks around), so the schema allows no other name
        json_schema_extra={
            "pattern": rf"^\s*({'|'.join(_any_case(n) for n in sorted(BUILTIN))})\s*$"
        },
    ),
]
RobotField = Annotated[
    Annotated[BuiltinName, Tag("built-in robot")] | Annotated[RobotDoc, Tag("inline robot")],
    Discriminator(lambda v: "built-in robot" if isinstance(v, str) else "inline robot"),
]


MPE_UM = (1.0, 500.0)  # a laser tracker's constant MPE term, um (0 allowed: none stated)
MPE_UM_PER_M_MAX = 100.0


class TrackerDoc(Doc):
    """The tracker's accuracy spec (maximum permissible error) and its traceability (serial,
    its own calibration certificate and when that falls due, the SMRs' ids); other keys are
    kept as given."""

    model_config = ConfigDict(extra="allow")
    MISSPELT_REFUSED = True
    mpe_um: NonNegative = 10.0
    mpe_um_per_m: NonNegative = 2.5
    serial: Label | None = Field(None, description="the tracker's serial number")
    certificate_id: Label | None = Field(
        None, description="the id of the tracker's own calibration certificate"
    )
    certificate_due: dt.date | None = Field(
        None,
        description="when the tracker's calibration falls due (YYYY-MM-DD): a certificate "
        "of a run after it says so and does not pass",
    )
    smr_ids: dict[str, Label] | None = Field(
        None, description="each SMR's own id (serial or inventory number), by target name"
    )

    @model_validator(mode="after")
    def _a_trackers_error(self):
        # A laser tracker's MPE is a few um to tens (+ a few um/m): a figure past these bounds is
        # another unit, and the floor it sets weighs the fit (a 10,000 um spec took a one-SMR
        # campaign's held-out error from 0.0165 to 0.908 mm, "deployable"), or makes every
        # verdict "an effect the model lacks" (0.01 um: 1,170x the floor)
        for key, low, high, per in (
            ("mpe_um", MPE_UM[0], MPE_UM[1], ""),
            ("mpe_um_per_m", 0.0, MPE_UM_PER_M_MAX, "/m"),
        ):
            v = getattr(self, key)
            if v == 0 or low <= v <= high:
                continue
            unit = "mm typed for um? " if v < low else "nm typed for um? "
            raise located(
                f"{v:g} um{per} is no laser tracker's MPE ({low:g} to {high:g} um{per}, or 0): "
                f"{unit}give the data sheet's figure in um (for instance 10 um + 2.5 um/m)",
                key,
            )
        return self

    @model_validator(mode="after")
    def _some_error(self):
        # A spec of no error at all makes the noise floor 0 mm, against which every verdict
        # (fit below the noise, held-out error past 3x the floor) means nothing.
        if self.mpe_um + self.mpe_um_per_m <= 0:
            raise located(
                "mpe_um and mpe_um_per_m are both 0: no tracker measures without error; give "
                "its data sheet's MPE (for instance 10 um + 2.5 um/m)",
                "mpe_um",
            )
        return self


class TrackerAddress(Doc):
    host: Label
    port: Annotated[int, Field(ge=1, le=65535), Whole]
    timeout_s: Timeout = 5.0

    @field_validator("host")
    @classmethod
    def _host(cls, host: str) -> str:
        host = host.strip()
        if not _is_host(host):
            raise located(f"{host!r} is not a host name or IP address")
        return host


class ControllerAddress(Doc):
    url: Label = Field(description="socket://host:port, rfc2217://host:port or a serial port")
    baudrate: Annotated[int, Field(ge=50, le=4_000_000), Whole] = 9600
    timeout_s: Timeout = 5.0

    @field_validator("url")
    @classmethod
    def _url(cls, url: str) -> str:
        url = url.strip()
        scheme, sep, rest = url.partition("://")
        if not sep:
            if not SERIAL_PORT.fullmatch(url):
                raise located(
                    f"{url!r} is neither socket://host:port nor a serial port such "
                    "as /dev/ttyUSB0 or COM3"
                )
            return url
        if scheme not in NETWORK_SCHEMES:
            raise located(
                f"scheme {scheme!r} is not one of "
                f"{', '.join(s + '://' for s in NETWORK_SCHEMES)} (or a serial port)"
            )
        host, colon, port = rest.split("?", 1)[0].rpartition(":")
        if not colon or not _is_host(host) or not port.isdigit() or not 1 <= int(port) <= 65535:
            raise located(f"{url!r}: expected {scheme}://host:port with a port in 1..65535")
        return url


class DevicesDoc(Doc):
    """Real instruments instead of the simulated cell."""

    tracker: TrackerAddress
    controller: ControllerAddress


# a positive length in mm, at most a metre (a tolerance, not a coordinate)
Tolerance = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0.0, le=1000.0)]


class CellDoc(Doc):
    """A cell.json: the robot, its SMR targets (flange frame, mm) and the tracker setup."""

    model_config = ConfigDict(extra="ignore", title="cell.json")
    MISSPELT_REFUSED = True
    robot: RobotField
    targets: dict[str, Point] = Field(
        description="nominal SMR positions in the flange frame, mm",
        json_schema_extra={
            "minProperties": 1,
            "maxProperties": SMRS_MAX,
            "propertyNames": {"pattern": f"^{TARGET_NAME_PATTERN}$"},
        },
    )
    base: RigidTransform | None = Field(
        None, description="4x4 guess of the robot base in the tracker frame"
    )
    tracker: TrackerDoc = Field(default_factory=TrackerDoc)
    payload_kg: NonNegative | None = None
    tolerance_mm: Tolerance | None = Field(
        None,
        description="the positioning accuracy the application needs, mm: a model whose held-out "
        "error exceeds it is not deployable",
    )
    repeatability_mm: Tolerance | None = Field(
        None,
        description="the arm's pose repeatability RP (ISO 9283) as its data sheet states it, "
        "mm: a verification's RP is decided against it, and the simulated arm scatters so "
        "about each pose it returns to",
    )
    devices: DevicesDoc | None = None

    @field_validator("targets")
    @classmethod
    def _targets(cls, targets: dict) -> dict:
        return apart(check_targets(targets))

    @field_validator("robot")
    @classmethod
    def _robot(cls, robot):
        if isinstance(robot, str):
            builtin_robot(robot)
        return robot

    @model_validator(mode="after")
    def _smr_ids_of_targets(self):
        for name in self.tracker.smr_ids or {}:
            if name not in self.targets:
                raise located(
                    f"SMR {name!r} is not among the targets ({', '.join(self.targets)})",
                    "tracker",
                    "smr_ids",
                    name,
                    key=True,
                )
        return self

    @model_validator(mode="after")
    def _devices_need(self):
        if self.devices is None:
            return self
        if self.base is None:
            # Planning and the tracker's first aims need the base: a search covers 10 to 50 mm
            # around each predicted SMR, not the metres between the tracker and an unknown base.
            raise located(
                "a cell with real devices needs a `base` guess (4x4, the robot base in the "
                "tracker frame, to within about 10 mm)",
                "devices",
                key=True,
            )
        if isinstance(self.robot, RobotDoc):
            within_builtin(self.robot.robot)
        return self

    @property
    def robot_model(self) -> Robot:
        """The solver's robot (radians)."""
        return builtin_robot(self.robot) if isinstance(self.robot, str) else self.robot.robot


def check_targets(targets: dict) -> dict:
    if not targets:
        raise located("at least one target is needed")
    if len(targets) > SMRS_MAX:
        raise located(
            f"{len(targets)} targets; a cell has at most {SMRS_MAX} SMRs (three fix the "
            "flange's pose, each more costs planning and calibration time)"
        )
    for name in targets:
        if not TARGET_NAME.fullmatch(name):
            raise located(
                f"target name {name!r} must be a letter followed by up to 15 letters, "
                "digits or '_'",
                name,
                key=True,
            )
    return targets


RADIANS_TURN = 2 * np.pi + 1e-6  # a whole turn in radians, as a number of degrees

# Two SMRs' centres lie at least a ball's diameter apart (12.7 mm for the smallest, 0.5-inch,
# SMR): closer ones are a layout in other units (metres, inches, centimetres) or a typing slip.
SMR_GAP_MIN_MM = 5.0
UNIT_GUESSES = (("centimetres", 10.0), ("inches", 25.4), ("metres", 1000.0))
FIXTURE_MM = 1000.0  # an SMR fixture holds its balls within this of the flange


def apart(targets: dict) -> dict:
    """The cell's SMR positions, refused where two lie closer than SMR_GAP_MIN_MM."""
    names = list(targets)
    xyz = np.array([[float(v) for v in targets[n]] for n in names]).reshape(len(names), 3)
    gap = np.linalg.norm(xyz[:, None] - xyz[None], axis=-1) + np.diag(np.full(len(names), np.inf))
    i, j = np.unravel_index(int(np.argmin(gap)), gap.shape)
    if len(names) < 2 or gap[i, j] >= SMR_GAP_MIN_MM:
        return targets
    # the units in which they would lie a ball apart and within a fixture's reach of the flange
    far = float(np.max(np.linalg.norm(xyz, axis=1)))
    units = [
        u for u, k in UNIT_GUESSES if gap[i, j] * k >= 2 * SMR_GAP_MIN_MM and far * k <= FIXTURE_MM
    ]
    hint = (
        f"the positions look like {' or '.join(units)}; give them in mm"
        if units
        else "check the positions"
    )
    raise located(
        f"SMRs {names[i]} and {names[j]} are {gap[i, j]:.3g} mm apart, closer than two SMR "
        f"balls can sit (their centres lie a diameter apart, 12.7 mm for a 0.5-inch SMR): {hint}",
        names[i],
        key=True,
    )


def check_transform(T: np.ndarray) -> None:
    """A rigid transform: last row [0, 0, 0, 1], orthonormal rotation, no reflection."""
    if np.max(np.abs(T[3] - [0, 0, 0, 1])) > 1e-9:
        raise located("the last row of a homogeneous transform must be [0, 0, 0, 1]", 3)
    R = T[:3, :3]
    err = np.max(np.abs(R.T @ R - np.eye(3)))
    if err > ORTHONORMAL_TOL:
        raise located(
            f"rotation part is not orthonormal (max |R'R - I| = {err:.3g}, "
            f"tolerance {ORTHONORMAL_TOL:g})"
        )
    if np.linalg.det(R) < 0:
        raise located("rotation part is a reflection (determinant -1), not a rotation")


def _rigid(T: list) -> list:
    check_transform(np.array(T, dtype=float))
    return T


# A 4x4 homogeneous transform of a rigid motion (cell.json's base guess, model.json's base)
RigidTransform = Annotated[Matrix4, AfterValidator(_rigid)]


def builtin_named(name: str) -> Robot | None:
    """The built-in robot an inline robot's name designates ("IRB 2600", "irb-2600"), if any."""
    return BUILTIN.get(re.sub(r"[^a-z0-9]", "", name.lower()))


def within_builtin(robot: Robot) -> None:
    """A real arm is never driven beyond its built-in model's limits, whatever the upload says."""
    model = builtin_named(robot.name)
    if model is None:
        return
    if robot.n_joints != model.n_joints:
        raise located(
            f"names the built-in {model.name}, which has "
            f"{model.n_joints} joints, not {robot.n_joints}",
            "robot",
            "joints",
        )
    tol = 1e-4  # degrees: the controller protocol's resolution
    for i, (mine, theirs) in enumerate(zip(robot.joints, model.joints)):
        lo, hi = np.rad2deg(mine.limits)
        blo, bhi = np.rad2deg(theirs.limits)
        if lo < blo - tol or hi > bhi + tol:
            raise located(
                f"[{lo:g}, {hi:g}] deg exceeds the built-in {model.name}'s "
                f"[{blo:g}, {bhi:g}] for joint {i + 1}; a cell with real devices "
                "may only narrow a built-in robot's limits",
                "robot",
                "joints",
                i,
                "limits",
            )


def _is_host(host: str) -> bool:
    """A host name or an IP address (IPv6 in brackets or bare)."""
    try:
        ipaddress.ip_address(host[1:-1] if host.startswith("[") and host.endswith("]") else host)
        return True
    except ValueError:
        return bool(HOST_NAME.fullmatch(host))


def _rad(deg: float) -> float:
    return float(np.deg2rad(deg))
