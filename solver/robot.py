"""Robot description: DH / modified DH joints, Hayati beta on parallel axes, built-in robots."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

CONVENTIONS = ("dh", "mdh")
# Two axes count as parallel when their twist is within this of 0 or 180 degrees.
PARALLEL_TOL_RAD = np.deg2rad(1.0)


@dataclass(frozen=True)
class Joint:
    """One revolute joint: lengths in mm, angles in radians."""

    a: float
    d: float
    theta: float
    alpha: float
    limits: tuple[float, float]
    beta: float = 0.0


@dataclass(frozen=True)
class Robot:
    """A serial revolute arm in standard (`dh`) or Craig's modified (`mdh`) convention."""

    name: str
    convention: str
    joints: tuple[Joint, ...]
    parallel: tuple[bool, ...] = field(default=())

    def __post_init__(self):
        if self.convention not in CONVENTIONS:
            raise ValueError(f"convention must be one of {CONVENTIONS}, not {self.convention!r}")
        if not self.parallel:
            object.__setattr__(self, "parallel", detect_parallel(self.convention, self.joints))

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def reach_mm(self) -> float:
        """How far the flange can be from the base's origin at most: each link translates by a
        and d along orthogonal axes, whatever the joints, in either convention."""
        return float(sum(np.hypot(j.a, j.d) for j in self.joints))

    @property
    def lower(self) -> np.ndarray:
        return np.array([j.limits[0] for j in self.joints])

    @property
    def upper(self) -> np.ndarray:
        return np.array([j.limits[1] for j in self.joints])

    def param_names(self) -> list[str]:
        """Names of the geometric parameters, in vector order."""
        names = []
        for i, _ in enumerate(self.joints, start=1):
            names += [f"theta{i}", f"d{i}", f"a{i}", f"alpha{i}"]
            if self.parallel[i - 1]:
                names.append(f"beta{i}")
        return names

    def param_vector(self) -> np.ndarray:
        """Geometric parameters (mm, rad) in the order of `param_names`."""
        values = []
        for j, par in zip(self.joints, self.parallel):
            values += [j.theta, j.d, j.a, j.alpha]
            if par:
                values.append(j.beta)
        return np.array(values, dtype=float)

    def with_params(self, values: np.ndarray) -> Robot:
        """The same robot with its geometric parameters replaced."""
        values = np.asarray(values, dtype=float)
        joints, k = [], 0
        for j, par in zip(self.joints, self.parallel):
            theta, d, a, alpha = values[k : k + 4]
            k += 4
            beta = 0.0
            if par:
                beta = values[k]
                k += 1
            joints.append(Joint(a=a, d=d, theta=theta, alpha=alpha, limits=j.limits, beta=beta))
        if k != len(values):
            raise ValueError(f"expected {k} geometric parameters, got {len(values)}")
        return Robot(self.name, self.convention, tuple(joints), self.parallel)

    def within_limits(self, q: np.ndarray, margin: float | np.ndarray = 0.0) -> np.ndarray:
        """Per pose, whether every joint angle (rad) lies within its limits shrunk by margin (rad,
        one for all joints or one a joint)."""
        q = np.atleast_2d(q)
        return np.all((q >= self.lower + margin) & (q <= self.upper - margin), axis=-1)


def detect_parallel(convention: str, joints) -> tuple[bool, ...]:
    """Which joints carry a Hayati beta: those whose twist makes two consecutive joint axes parallel.

    In `dh`, joint i's alpha is the twist between axis i and axis i+1, so the last joint (whose
    z is the flange, not an axis) never qualifies. In `mdh`, joint i's alpha is the twist between
    axis i-1 and axis i, so the first joint (twist to the base) never qualifies.
    """
    flags = []
    n = len(joints)
    for i, j in enumerate(joints):
        near = abs(np.sin(j.alpha)) < np.sin(PARALLEL_TOL_RAD)
        if convention == "dh":
            flags.append(bool(near and i < n - 1))
        else:
            flags.append(bool(near and i > 0))
    return tuple(flags)


def robot_from_degrees(name: str, convention: str, rows) -> Robot:
    """A robot from rows of (a, d, theta_deg, alpha_deg, (lo_deg, hi_deg))."""
    joints = tuple(
        Joint(
            a=float(a),
            d=float(d),
            theta=np.deg2rad(t),
            alpha=np.deg2rad(al),
            limits=(np.deg2rad(lim[0]), np.deg2rad(lim[1])),
        )
        for a, d, t, al, lim in rows
    )
    return Robot(name, convention, joints)


# The seed paper's Table 2 (standard DH, mm and degrees); limits from ABB's IRB 2600 data sheet.
IRB2600 = robot_from_degrees(
    "irb2600",
    "dh",
    [
        (150.0, 445.0, 0.0, -90.0, (-180.0, 180.0)),
        (900.0, 0.0, -90.0, 0.0, (-95.0, 155.0)),
        (150.0, 0.0, 0.0, -90.0, (-180.0, 75.0)),
        (0.0, 938.0, 0.0, 90.0, (-400.0, 400.0)),
        (0.0, 0.0, 180.0, 90.0, (-120.0, 120.0)),
        (0.0, 200.0, 0.0, 0.0, (-400.0, 400.0)),
    ],
)

# Standard DH, KUKA KR 16-like proportions; axes 2 and 3 parallel (the tests' and the suite's
# second geometry, not a built-in cell).
KUKA_LIKE = robot_from_degrees(
    "kuka-like",
    "dh",
    [
        (260.0, 675.0, 0.0, -90.0, (-185.0, 185.0)),
        (680.0, 0.0, -90.0, 0.0, (-65.0, 140.0)),
        (35.0, 0.0, 0.0, -90.0, (-210.0, 66.0)),
        (0.0, 670.0, 0.0, 90.0, (-350.0, 350.0)),
        (0.0, 0.0, 0.0, -90.0, (-130.0, 130.0)),
        (0.0, 158.0, 0.0, 0.0, (-350.0, 350.0)),
    ],
)

BUILTIN = {"irb2600": IRB2600}
