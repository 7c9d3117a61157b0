"""Physics the geometric model lacks: one class per effect, made from a spec by `make_effect`.

These are the simulator's hidden truth; the diagnosis's effects of the same names
(solver/vocabulary.py) are what it can fit. They share no code on purpose: a judge that shares
code with the thing it judges proves nothing.
"""

from __future__ import annotations

import difflib
import math

import numpy as np

from robocal.solver import chain
from robocal.solver.kinematics import joint_ops, translation
from robocal.solver.robot import Robot

G = 9.81  # m/s^2, along the cell's `down` (-z of the base frame on a floor-mounted arm)
REFERENCE_TEMP_C = 20.0  # ISO 1 reference temperature: zero growth until a campaign sets T0
EFFECT_STREAM = 0xEFFEC7  # effects draw from their own stream, so the cell's geometry is unchanged


def link_frames(robot: Robot, q):
    """Per joint in the base frame: axis, a point on it (m, N, 3), its link's frame R (m, N, 3, 3), o.

    One walk down the arm: a joint's axis and point right after its rotation, its link's frame
    (the convention's frame J, the flange for J = N) after the last motion of its parameters.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    ops = joint_ops(robot)
    ends = np.cumsum([5 if par else 4 for par in robot.parallel])
    owner = np.searchsorted(ends, [op.param for op in ops], side="right")
    M = chain.frames(np.eye(4), q.shape[0])
    axes, points, R, o = [], [], [], []
    for k, op in enumerate(chain.walk(ops, robot.param_vector(), q, M)):
        if op.kind == "r" and op.joint >= 0:
            axes.append(M[:, op.axis].T.copy())
            points.append(M[:, 3].T.copy())
        if k + 1 == len(ops) or owner[k + 1] != owner[k]:
            Rj, oj = chain.split(M)
            R.append(Rj)
            o.append(oj)
    return (
        np.stack(axes, axis=1),
        np.stack(points, axis=1),
        np.stack(R, axis=1),
        np.stack(o, axis=1),
    )


class MassModel:
    """Point masses fixed to links: a centre of gravity (mm, in its link's frame) per body."""

    def __init__(self, link, mass_kg, cog_mm):
        self.link = np.asarray(link, dtype=int)  # 0-based joint whose link carries the body
        self.mass_kg = np.asarray(mass_kg, dtype=float)
        self.cog_mm = np.asarray(cog_mm, dtype=float).reshape(-1, 3)

    @classmethod
    def random(cls, robot: Robot, rng) -> MassModel:
        """Per link 5 kg + 25 kg/m of length, x U(0.5, 1.5), near the link; a 2-20 kg payload."""
        n = robot.n_joints
        _, points, R, o = link_frames(robot, np.zeros((1, n)))
        ends = np.vstack(
            [points[0, 1:], o[0, -1:]]
        )  # a link runs from its axis to the next (flange)
        links, masses, cogs = [], [], []
        for j in range(n):
            start, end = (R[0, j].T @ (p - o[0, j]) for p in (points[0, j], ends[j]))  # link frame
            length_m = np.abs(end - start).sum() / 1000.0  # |a| + |d|
            masses.append((5.0 + 25.0 * length_m) * rng.uniform(0.5, 1.5))
            # anywhere in the box the link spans, 50 mm of flesh around its kinematic skeleton
            cogs.append(rng.uniform(np.minimum(start, end) - 50.0, np.maximum(start, end) + 50.0))
            links.append(j)
        direction = rng.normal(size=3)
        r = 150.0 * rng.uniform() ** (1 / 3)  # uniform in a 150 mm ball about the flange
        links.append(n - 1)
        masses.append(rng.uniform(2.0, 20.0))
        cogs.append(r * direction / np.linalg.norm(direction))
        return cls(links, masses, cogs)

    def positions(self, robot: Robot, q) -> np.ndarray:
        """Centres of gravity (m, bodies, 3) in the base frame, mm."""
        _, _, R, o = link_frames(robot, q)
        return self._place(R, o)

    def _place(self, R, o):
        return o[:, self.link] + np.einsum("mbij,bj->mbi", R[:, self.link], self.cog_mm)

    def torques(self, robot: Robot, q, down=(0.0, 0.0, -1.0)) -> np.ndarray:
        """Gravity torque (m, N) about each joint axis, N m: z_J . sum_(bodies beyond J) r x m g,
        gravity along `down` (a unit vector in the base frame)."""
        axes, points, R, o = link_frames(robot, q)
        r = self._place(R, o)
        force = G * self.mass_kg[:, None] * np.asarray(down, dtype=float)[None, :]
        tau = np.empty(axes.shape[:2])
        for j in range(axes.shape[1]):
            beyond = self.link >= j
            lever_m = (r[:, beyond] - points[:, j, None]) / 1000.0
            moment = np.cross(lever_m, force[beyond]).sum(axis=1)
            tau[:, j] = np.einsum("mi,mi->m", moment, axes[:, j])
        return tau

    def describe(self) -> dict:
        bodies = [
            {"link": int(j) + 1, "mass_kg": float(mk), "cog_mm": [float(v) for v in c]}
            for j, mk, c in zip(self.link[:-1], self.mass_kg[:-1], self.cog_mm[:-1])
        ]
        return {
            "frames": "each link's cog in the convention's frame of its joint (frame J); "
            "the payload's in the flange frame",
            "links": bodies,
            "payload_kg": float(self.mass_kg[-1]),
            "payload_cog_mm": [float(v) for v in self.cog_mm[-1]],
        }


class _Effect:
    """Shared parts: the spec fields and a no-op for the hook an effect does not use."""

    name = ""
    unit = ""
    default = 0.0
    law = ""  # what it does, for `simulate --help`
    takes_joint = takes_harmonic = False
    first_joint = 1  # lowest joint it can act on (from 1)
    signed = False  # a negative magnitude means something (else it is refused)
    # the largest |magnitude| a cell can have, beyond which a spec is a typo or another unit,
    # not physics: far past any real arm's (10-100x), and past the diagnosis suite's aimed
    # magnitudes (bench.diagnose_suite, 2000 seeds: at most 0.43 of it, joint_scale's 4300 ppm;
    # joint_periodic 1.23 deg, thermal_drift 1000 ppm/degC)
    most = math.inf

    def __init__(self, magnitude: float, joint: int | None = None, harmonic: int | None = None):
        self.magnitude = float(magnitude)
        self.joint = joint  # 0-based inside the code
        self.harmonic = harmonic

    def joint_offsets(self, cell, q, time_s, temp_c):
        return None

    def base_motion(self, cell, time_s, temp_c):
        return None

    def _dq(self, q, values):
        dq = np.zeros_like(np.atleast_2d(q), dtype=float)
        dq[:, self.joint] = values
        return dq

    def label(self) -> str:
        """The effect as a spec with its magnitude and unit, e.g. `joint_periodic:3:2=0.01 deg`."""
        head = self.name
        if self.joint is not None:
            head += f":{self.joint + 1}"
        if self.harmonic is not None:
            head += f":{self.harmonic}"
        return f"{head}={self.magnitude:g} {self.unit}"

    def describe(self) -> dict:
        """Name, joint (from 1), harmonic, magnitude and unit, and the drawn hidden parameters."""
        return {
            "name": self.name,
            "joint": None if self.joint is None else self.joint + 1,
            "harmonic": self.harmonic,
            "magnitude": self.magnitude,
            "unit": self.unit,
            **self.hidden(),
        }

    def hidden(self) -> dict:
        return {}


class JointCompliance(_Effect):
    """dq_J = c tau_J(q): the joint gives way under the gravity torque of a random mass model."""

    name, unit, default, takes_joint = "joint_compliance", "urad/(N m)", 0.3, True
    most = 1000.0  # a heavy arm's joints: 1 to 5; a small wrist's tens
    law = "dq = compliance x gravity torque"

    def __init__(self, cell, rng, magnitude, joint, harmonic=None):
        super().__init__(magnitude, joint)
        self.mass = MassModel.random(cell.true_robot, rng)

    def joint_offsets(self, cell, q, time_s, temp_c):
        return self._dq(
            q,
            1e-6 * self.magnitude * self.mass.torques(cell.true_robot, q, cell.down)[:, self.joint],
        )

    def hidden(self) -> dict:
        return self.mass.describe()


class JointPeriodic(_Effect):
    """dq_J = A sin(K q_J + phase): a cyclic transmission or encoder error."""

    name, unit, default, takes_joint, takes_harmonic = "joint_periodic", "deg", 0.01, True, True
    most = 5.0  # a reducer's transmission error: arc seconds to minutes
    law = "dq = A sin(K q + phase), K 1 or 2 drawn if omitted"

    def __init__(self, cell, rng, magnitude, joint, harmonic=None):
        super().__init__(
            magnitude, joint, int(rng.integers(1, 3)) if harmonic is None else harmonic
        )
        self.phase = rng.uniform(0.0, 2 * np.pi)

    def joint_offsets(self, cell, q, time_s, temp_c):
        qj = np.atleast_2d(q)[:, self.joint]
        return self._dq(q, np.deg2rad(self.magnitude) * np.sin(self.harmonic * qj + self.phase))

    def hidden(self) -> dict:
        return {"phase_deg": float(np.rad2deg(self.phase))}


class JointScale(_Effect):
    """dq_J = s q_J: a gear-ratio or encoder scale error."""

    name, unit, default, takes_joint, signed = "joint_scale", "ppm", 100.0, True, True
    most = 1e4  # 1 %
    law = "dq = s q"

    def __init__(self, cell, rng, magnitude, joint, harmonic=None):
        super().__init__(magnitude, joint)

    def joint_offsets(self, cell, q, time_s, temp_c):
        return self._dq(q, 1e-6 * self.magnitude * np.atleast_2d(q)[:, self.joint])


class ThermalDrift(_Effect):
    """The arm grows with the air temperature: base-frame points scale by 1 + kappa (T - T0)."""

    name, unit, default, signed = "thermal_drift", "ppm/degC", 50.0, True
    most = 5000.0  # steel 11.5, aluminium 23
    law = "growth per degree of air, which then warms 2-5 degC"

    def __init__(self, cell, rng, magnitude, joint=None, harmonic=None):
        super().__init__(magnitude)
        self.temperature_rise_c = rng.uniform(2.0, 5.0)  # the cell warms so the effect shows
        self.t0_c = REFERENCE_TEMP_C

    def start_campaign(self, cell, time_s, temp_c):
        self.t0_c = float(temp_c.flat[0])  # the first reading's air

    def base_motion(self, cell, time_s, temp_c):
        if temp_c is None:
            return None
        s = 1.0 + 1e-6 * self.magnitude * (np.asarray(temp_c, dtype=float) - self.t0_c)
        m = np.zeros((s.size, 4, 4))
        m[:, 0, 0] = m[:, 1, 1] = m[:, 2, 2] = s
        m[:, 3, 3] = 1.0
        return m

    def hidden(self) -> dict:
        return {"t0_c": self.t0_c, "temperature_rise_c": float(self.temperature_rise_c)}


class BaseShift(_Effect):
    """At at_s the base moves `magnitude` mm and turns magnitude/2000 rad, in random directions."""

    name, unit, default = "base_shift", "mm", 0.2
    most = 100.0
    law = "a rigid move at a random time mid-campaign"

    def __init__(self, cell, rng, magnitude, joint=None, harmonic=None):
        super().__init__(magnitude)
        self.direction = _unit(rng.normal(size=3))
        self.axis = _unit(rng.normal(size=3))
        self.fraction = rng.uniform(0.3, 0.7)  # of the campaign's duration
        self.at_s = None  # known once a campaign starts

    def start_campaign(self, cell, time_s, temp_c):
        self.at_s = float(self.fraction * np.nanmax(time_s))

    @property
    def motion(self) -> np.ndarray:
        """The 4x4 move of the base, in the base frame."""
        m = translation(*(self.magnitude * self.direction))
        m[:3, :3] = _rotation(self.axis, self.magnitude / 2000.0)
        return m

    def base_motion(self, cell, time_s, temp_c):
        if time_s is None or self.at_s is None:
            return None
        after = np.asarray(time_s, dtype=float) >= self.at_s  # NaN (no time) counts as before
        return np.where(after[:, None, None], self.motion, np.eye(4))

    def hidden(self) -> dict:
        return {
            "at_s": self.at_s,
            "at_fraction": float(self.fraction),
            "translation_mm": [float(v) for v in self.magnitude * self.direction],
            "rotation_axis": [float(v) for v in self.axis],
            "rotation_deg": float(np.rad2deg(self.magnitude / 2000.0)),
        }


class JointBacklash(_Effect):
    """dq_J = -b d_J: lost motion in a gear, the joint lags by b behind the direction d of its last move.

    The direction is state: the last commanded angle and the sign of the last move, so that a
    campaign computed at once (poses in visit order) and a cell driven pose by pose (the
    simulated controller, read again for each SMR) see the same physics. A joint that has not
    moved yet rests mid-play (d = 0), as the diagnosis assumes for the first pose.
    """

    name, unit, default, takes_joint = "joint_backlash", "deg", 0.01, True
    most = 5.0  # a worn reducer's: a few hundredths
    law = "dq = -b x the sign of the joint's last move, state kept pose to pose"

    def __init__(self, cell, rng, magnitude, joint, harmonic=None):
        super().__init__(magnitude, joint)
        self.start_campaign(cell, None, None)

    def start_campaign(self, cell, time_s, temp_c):
        """A new campaign: no move seen yet."""
        self._last_q = None  # the joint's last commanded angle, rad
        self._direction = 0.0
        self._seen = None  # (poses, their directions): reading the same poses again moves nothing

    def follow(self, q) -> np.ndarray:
        """Directions (m,) of the joint's last move at each pose, the poses visited in row order."""
        out = np.empty(len(q))
        for i, v in enumerate(np.atleast_2d(q)[:, self.joint]):
            if self._last_q is not None and v != self._last_q:
                self._direction = float(np.sign(v - self._last_q))
            self._last_q = v
            out[i] = self._direction
        return out

    def joint_offsets(self, cell, q, time_s, temp_c):
        q = np.atleast_2d(q)
        if self._seen is None or not np.array_equal(self._seen[0], q):
            self._seen = (q.copy(), self.follow(q))
        return self._dq(q, -np.deg2rad(self.magnitude) * self._seen[1])


class JointCoupling(_Effect):
    """dq_J = c q_(J-1): joint J turns with the joint before it (a coupled wrist); simulator only."""

    name, unit, default, takes_joint, signed = "joint_coupling", "ppm", 200.0, True, True
    most = 1e4  # 1 %
    law = "dq_J = c q_(J-1), a wrist coupling"
    first_joint = 2

    def __init__(self, cell, rng, magnitude, joint, harmonic=None):
        super().__init__(magnitude, joint)

    def joint_offsets(self, cell, q, time_s, temp_c):
        return self._dq(q, 1e-6 * self.magnitude * np.atleast_2d(q)[:, self.joint - 1])


def _unit(v):
    return v / np.linalg.norm(v)


def _rotation(axis, angle) -> np.ndarray:
    """3x3 rotation by angle (rad) about a unit axis (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


EFFECTS = {
    e.name: e
    for e in (
        JointCompliance,
        JointPeriodic,
        JointScale,
        ThermalDrift,
        BaseShift,
        JointBacklash,
        JointCoupling,
    )
}
SPEC_HELP = "NAME[:JOINT[:HARMONIC]][=MAGNITUDE]"


def make_effect(spec: str, cell, rng):
    """The effect a spec `NAME[:JOINT[:HARMONIC]][=MAGNITUDE]` names, on this cell; ValueError if bad."""
    head, eq, mag_text = str(spec).strip().partition("=")
    name, *fields = [f.strip() for f in head.split(":")]
    cls = EFFECTS.get(name)
    if cls is None:
        close = difflib.get_close_matches(name, list(EFFECTS), n=1)
        raise ValueError(
            f"effect {spec!r}: unknown effect {name!r}; "
            + (f"did you mean {close[0]!r}? " if close else "")
            + f"choose from {', '.join(EFFECTS)}"
        )
    n = cell.true_robot.n_joints
    allowed = int(cls.takes_joint) + int(cls.takes_harmonic)
    if len(fields) > allowed:
        what = {0: "no joint", 1: "only a joint"}.get(allowed, "a joint and a harmonic")
        raise ValueError(f"effect {spec!r}: {name} takes {what} ({_grammar(cls)})")
    joint = harmonic = None
    if cls.takes_joint:
        if not fields or not fields[0]:
            raise ValueError(f"effect {spec!r}: {name} needs a joint, 1 to {n} ({_grammar(cls)})")
        joint = _integer(spec, "joint", fields[0])
        if not 1 <= joint <= n:
            raise ValueError(
                f"effect {spec!r}: joint {joint} is not one of the robot's joints 1 to {n}"
            )
        if joint < cls.first_joint:
            raise ValueError(f"effect {spec!r}: {name} acts on joints {cls.first_joint} to {n}")
        joint -= 1
    if len(fields) > 1:
        harmonic = _integer(spec, "harmonic", fields[1])
        if harmonic < 1:
            raise ValueError(
                f"effect {spec!r}: the harmonic must be a positive integer, not {harmonic}"
            )
    magnitude = cls.default
    if eq:
        try:
            magnitude = float(mag_text)
        except ValueError:
            raise ValueError(
                f"effect {spec!r}: magnitude {mag_text.strip()!r} is not a number (in {cls.unit})"
            ) from None
        if not math.isfinite(magnitude):
            raise ValueError(f"effect {spec!r}: magnitude must be finite")
        if magnitude < 0 and not cls.signed:
            raise ValueError(f"effect {spec!r}: magnitude must not be negative (in {cls.unit})")
        if abs(magnitude) > cls.most:
            m = f"{cls.most:g}"
            raise ValueError(
                f"effect {spec!r}: magnitude {magnitude:g} {cls.unit} is past any real cell's "
                f"{name} (bound {'-' + m if cls.signed else '0'} to {m} {cls.unit})"
            )
    return cls(cell, rng, magnitude, joint, harmonic)


def make_effects(specs, cell, seed: int) -> list:
    """Effects for several specs, their hidden parameters drawn from a stream of their own per seed."""
    rng = np.random.default_rng([EFFECT_STREAM, seed])
    return [make_effect(s, cell, rng) for s in specs]


def _grammar(cls) -> str:
    return (
        cls.name
        + (":JOINT" if cls.takes_joint else "")
        + ("[:HARMONIC]" if cls.takes_harmonic else "")
        + f"[=MAGNITUDE in {cls.unit}]"
    )


def spec_help(diagnosed) -> str:
    """Every effect's spec, law and default, those outside `diagnosed` (names) marked simulator-only."""

    def one(cls):
        head = cls.name + (":J" if cls.takes_joint else "") + ("[:K]" if cls.takes_harmonic else "")
        return f"{head} ({cls.law}, default {cls.default:g} {cls.unit})"

    inside = [one(c) for c in EFFECTS.values() if c.name in diagnosed]
    outside = [one(c) for c in EFFECTS.values() if c.name not in diagnosed]
    return "; ".join(inside) + (
        "; simulator only, outside the diagnosis vocabulary: " + "; ".join(outside)
        if outside
        else ""
    )


def _integer(spec, what, text) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"effect {spec!r}: {what} {text!r} is not an integer") from None
