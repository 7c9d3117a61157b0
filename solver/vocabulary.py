"""The diagnosis vocabulary: one class per effect, each registered once in KINDS, and the
Extension that names one of them in a model (with the Inputs its basis reads).

A kind says everything the program knows of one effect: how its extension acts (on one joint's
angle, or on the SMR centres), its basis on the data and its parameter count, its label, its
parameters in edge units and the sentence that states them, its place in the report and in
`model.json`, the axes of its figure, and the candidates of it a campaign can show. Adding an
effect to the diagnosis is adding one class here (and, to simulate it, its physics in
drivers/effects.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .extrapolation import gravity_loaded
from .gravity import (
    LINK_TERMS,
    gravity_basis,
    gravity_in_base,
    nominal_masses,
    select_independent,
)
from .motion import last_motion

MDEG_PER_RAD = np.degrees(1.0) * 1000.0
THERMAL_MIN_SPAN_C = 0.3  # below this air-temperature span, growth is sought against time instead


@dataclass
class Inputs:
    """What extensions depend on, per pose and reading: joints, time, temperature, last motion."""

    q: np.ndarray  # (m, n) rad
    time_s: np.ndarray | None = None  # (m, K)
    temp_c: np.ndarray | None = None  # (m, K)
    # (m, n) sign of each joint's last move before the pose, from the whole campaign's order
    motion: np.ndarray | None = None
    # (m, n) rad the joints the arm came from (NaN rows: not given); they decide the motion
    prev_q: np.ndarray | None = None

    def __post_init__(self):
        # A reading without its time or temperature (a blank field: not recorded) takes its
        # pose's: the SMRs of a pose are read seconds apart, the air does not change between.
        self.time_s, self.temp_c = (_pose_filled(a) for a in (self.time_s, self.temp_c))
        if self.motion is None:
            self.motion = last_motion(self.q, self.time_s, self.prev_q)

    def subset(self, idx) -> Inputs:
        pick = lambda a: None if a is None else a[idx]  # noqa: E731
        return Inputs(
            self.q[idx], pick(self.time_s), pick(self.temp_c), pick(self.motion), pick(self.prev_q)
        )


def _pose_filled(a: np.ndarray | None) -> np.ndarray | None:
    """A per-reading column (m, K) with each NaN replaced by its pose's mean (NaN where a pose
    has none; None where no reading has one)."""
    if a is None or np.isfinite(a).all():
        return a
    a = np.asarray(a, dtype=float)
    given = np.isfinite(a)
    if not given.any():
        return None  # a column of blanks: not recorded
    n = given.sum(axis=1, keepdims=True)
    mean = np.where(given, a, 0.0).sum(axis=1, keepdims=True) / np.maximum(n, 1)
    return np.where(given, a, np.where(n > 0, mean, np.nan))


@dataclass
class Extension:
    """One extension: its kind, where it acts, and its fitted coefficients."""

    name: str
    joint: int | None = None  # 0-based
    harmonic: int | None = None
    at_s: float | None = None
    t_ref: float | None = None  # thermal: temperature (or time) of zero growth
    variable: str | None = None  # thermal: "temp_c" or "time_s"
    origin: np.ndarray | None = None  # base shift: centre of the rotation (the data's centroid)
    coef: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # compliance: raw gravity-basis columns kept and the gravity direction in the base frame
    keep: np.ndarray | None = None
    gravity: np.ndarray | None = None
    # compliance under the nominal mass model: fixed weights of the raw gravity basis (one
    # stiffness fitted), instead of the kept columns' masses fitted one by one
    masses: np.ndarray | None = None
    # scale, periodic: the joint range (lo, hi) rad the effect is held to, at its edge value
    # beyond it, when its look-alikes part past the range it was fitted on (solver.lookalike)
    held: np.ndarray | None = None

    @property
    def kind(self):
        """Its class in the vocabulary (solver.vocabulary), which knows everything else about it."""
        return KINDS[self.name]

    @property
    def is_joint(self) -> bool:
        return self.kind.is_joint

    @property
    def n_params(self) -> int:
        return self.kind.n_params(self)

    def label(self) -> str:
        return self.kind.label(self)


class Effect:
    """What every kind answers; the defaults suit a joint effect with a fixed parameter count."""

    name = ""
    is_joint = True  # dq_joint = basis @ coef; else the extension moves the SMR centres
    params = 1
    once = False  # at most one per model: it acts on the whole cell, not on one joint
    located_in_time = False  # its time is located once on the whole campaign (base shift)
    stored: tuple = ()  # Extension fields kept in model.json beside name, joint and coef: (field, type)
    report_keys: tuple = ()  # Extension fields the report names beside name and joint

    def n_params(self, ext: Extension) -> int:
        return self.params

    def label(self, ext: Extension) -> str:
        return self.name if ext.joint is None else f"{self.name}({ext.joint + 1})"

    def basis(self, ext: Extension, layout, x, inputs: Inputs) -> np.ndarray:
        """(m, P) for a joint effect (dq = basis @ coef), (m, K) per reading for a point effect."""
        raise NotImplementedError

    def candidates(self, layout, x, inputs: Inputs) -> list[Extension]:
        """The extensions of this kind the data could show (one per joint by default)."""
        return [Extension(self.name, joint=j) for j in range(layout.robot.n_joints)]

    def parameters(self, ext: Extension, basis) -> dict:
        """The fitted parameters in mm, degrees, ppm and seconds."""
        raise NotImplementedError

    def evidence(self, ext: Extension, p: dict, gain: str) -> str:
        """One sentence a person can check against the figure; `gain` says what modelling it buys."""
        raise NotImplementedError

    def needs(self, ext: Extension) -> str | None:
        """The pose column (`time_s`, `temp_c`) its prediction cannot do without, if any."""
        return None

    def to_json(self, ext: Extension) -> dict:
        """Its fields in model.json beyond name, joint and coef."""
        out = {}
        for key, kind in self.stored:
            v = getattr(ext, key)
            out[key] = np.asarray(v, dtype=float).tolist() if kind == "vector" else v
        return out

    def from_json(self, read) -> dict:
        """Extension keywords from model.json; `read.<type>(key)` reads a required field."""
        return {key: getattr(read, kind)(key) for key, kind in self.stored}

    def figure(self, ext: Extension, inputs: Inputs, expected) -> dict:
        """The figure's variable per pose and its axis labels."""
        assert ext.joint is not None  # a joint-periodic term names its joint
        j = ext.joint + 1
        return {
            "x": np.degrees(inputs.q[:, ext.joint]),
            "x_label": f"q{j} / deg",
            "y_label": f"joint {j} error / mdeg",
        }

    def signature_axis(self, ext: Extension, Jq, p, layout, x):
        """Per reading, the direction (N, 3) that measures the effect in a residual, and its scale."""
        return Jq[ext.joint], MDEG_PER_RAD


class HeldJointEffect(Effect):
    """A function of its own joint's angle, which may be held to a joint range (Extension.held):
    past it the effect keeps its value at the range's edge. Stored as `held_range_deg`."""

    KEY = "held_range_deg"

    def angle(self, ext, inputs) -> np.ndarray:
        """Its joint's angle (m,) rad, within the held range when there is one."""
        q = inputs.q[:, ext.joint]
        return q if ext.held is None else np.clip(q, ext.held[0], ext.held[1])

    def to_json(self, ext):
        out = super().to_json(ext)
        if ext.held is not None:
            out[self.KEY] = np.degrees(np.asarray(ext.held, dtype=float)).tolist()
        return out

    def from_json(self, read):
        out = super().from_json(read)
        if read.has(self.KEY):
            lo_hi = read.vector(self.KEY)
            if len(lo_hi) != 2 or not lo_hi[0] <= lo_hi[1]:
                raise read.error(self.KEY, "expected [low, high] degrees, low <= high")
            out["held"] = np.radians(lo_hi)
        return out


class JointPeriodic(HeldJointEffect):
    """dq_j = a sin(k q_j) + b cos(k q_j): a cyclic transmission or encoder error."""

    name, params, stored, report_keys = (
        "joint_periodic",
        2,
        (("harmonic", "integer"),),
        ("harmonic",),
    )
    HARMONICS = (1, 2)

    def label(self, ext):
        return f"{self.name}({ext.joint + 1},k={ext.harmonic})"

    def basis(self, ext, layout, x, inputs):
        kq = ext.harmonic * self.angle(ext, inputs)
        return np.stack([np.sin(kq), np.cos(kq)], axis=1)

    def candidates(self, layout, x, inputs):
        return [
            Extension(self.name, joint=j, harmonic=k)
            for j in range(layout.robot.n_joints)
            for k in self.HARMONICS
        ]

    def parameters(self, ext, basis):
        c = np.asarray(ext.coef, dtype=float)
        return {
            "amplitude_deg": float(np.degrees(np.hypot(c[0], c[1]))),
            "phase_deg": float(np.degrees(np.arctan2(c[1], c[0]))),
            "harmonic": ext.harmonic,
        }

    def evidence(self, ext, p, gain):
        j = ext.joint + 1
        return (
            f"Joint {j}'s residual rotation follows {p['amplitude_deg'] * 1000:.1f} mdeg x "
            f"sin({ext.harmonic} q{j} {p['phase_deg']:+.0f} deg); {gain}."
        )


class JointScale(HeldJointEffect):
    """dq_j = s q_j: a gear-ratio or encoder scale error."""

    name = "joint_scale"

    def basis(self, ext, layout, x, inputs):
        return self.angle(ext, inputs)[:, None]

    def parameters(self, ext, basis):
        return {"scale_ppm": float(ext.coef[0] * 1e6)}

    def evidence(self, ext, p, gain):
        return (
            f"Joint {ext.joint + 1}'s residual rotation grows linearly with its angle, "
            f"{p['scale_ppm']:.0f} ppm; {gain}."
        )


class JointCompliance(Effect):
    """dq_j = one stiffness x the gravity torque of the nominal mass model (the physics'
    parsimony: it extrapolates); that torque with the mass moments of the link the joint drives
    fitted beside it (the body nearest the joint, a counterbalance acting on its angle); or the
    torque's terms of every link beyond j with their masses and mass moments fitted. The richer
    models are taken only where they pay off on their own test."""

    name = "joint_compliance"

    def n_params(self, ext):
        fitted = 0 if ext.keep is None else int(ext.keep.sum())
        return fitted + (1 if ext.masses is not None else 0)

    def label(self, ext):
        if ext.masses is None:
            return f"{self.name}({ext.joint + 1}, masses fitted)"
        if ext.keep is not None:
            return f"{self.name}({ext.joint + 1}, its link's masses fitted)"
        return f"{self.name}({ext.joint + 1})"

    def basis(self, ext, layout, x, inputs):
        raw = gravity_basis(layout, x, inputs.q, ext.joint, ext.gravity)
        cols = [] if ext.masses is None else [raw @ ext.masses[:, None]]
        return np.concatenate(cols + ([] if ext.keep is None else [raw[:, ext.keep]]), axis=1)

    def candidates(self, layout, x, inputs):
        g = gravity_in_base(layout, x)
        # a vertical axis carries next to no gravity torque: its driven link's moment fitted
        # would be a first harmonic of its angle under another name
        loaded = gravity_loaded(layout, x, inputs.q)
        out = []
        for j in range(layout.robot.n_joints):
            raw = gravity_basis(layout, x, inputs.q, j, g)
            keep = select_independent(raw)
            if not keep.any():
                continue
            w = nominal_masses(layout, x, j)
            nominal = raw @ w[:, None]
            if select_independent(nominal).any():
                out.append(Extension(self.name, joint=j, gravity=g, masses=w))
            if j in loaded:
                # the driven link's columns (gravity_basis's first four) beside the nominal torque
                own = select_independent(np.concatenate([nominal, raw[:, :LINK_TERMS]], axis=1))
                mid = np.zeros(len(keep), dtype=bool)
                mid[:LINK_TERMS] = own[1:]
                if own[0] and 0 < mid.sum() < keep.sum() - 1:
                    out.append(Extension(self.name, joint=j, gravity=g, masses=w, keep=mid))
            if keep.sum() > 1:
                out.append(Extension(self.name, joint=j, keep=keep, gravity=g))
        return out

    def parameters(self, ext, basis):
        dq = basis @ np.asarray(ext.coef, dtype=float)
        dq = dq - dq.mean()  # the constant part is the joint's offset
        return {
            "deflection_rms_deg": float(np.degrees(np.sqrt(np.mean(dq * dq)))),
            "deflection_range_deg": float(np.degrees(dq.max() - dq.min())),
            "gravity_terms": int(len(ext.coef)),  # 1: one stiffness on the nominal mass model
        }

    def evidence(self, ext, p, gain):
        return (
            f"Joint {ext.joint + 1}'s residual rotation follows the gravity torque it carries "
            f"({p['deflection_range_deg'] * 1000:.1f} mdeg peak to peak over the poses); {gain}."
        )

    def to_json(self, ext):
        out = {"gravity": np.asarray(ext.gravity, dtype=float).tolist()}
        if ext.masses is not None:
            out["masses"] = np.asarray(ext.masses, dtype=float).tolist()
        if ext.keep is not None:
            out["gravity_terms"] = np.flatnonzero(ext.keep).tolist()
            out["gravity_terms_total"] = len(ext.keep)
        return out

    def from_json(self, read):
        out = {"gravity": read.vector("gravity")}
        if read.has("masses"):
            out["masses"] = read.vector("masses")
        if not read.has("masses") or read.has("gravity_terms"):
            keep = np.zeros(read.integer("gravity_terms_total"), dtype=bool)
            terms = read.vector("gravity_terms")
            if np.any(terms != np.round(terms)) or np.any((terms < 0) | (terms >= len(keep))):
                raise read.error("gravity_terms", f"expected indices 0 to {len(keep) - 1}")
            keep[terms.astype(int)] = True
            out["keep"] = keep
        return out

    def figure(self, ext, inputs, expected):
        return {
            "x": expected,
            "x_label": "unabsorbed gravity deflection / mdeg",
            "y_label": f"joint {ext.joint + 1} error / mdeg",
        }


class JointBacklash(Effect):
    """dq_j = c d_j, d_j the sign of the joint's last motion: lost motion in a gear (b = -c)."""

    name = "joint_backlash"

    def basis(self, ext, layout, x, inputs):
        return inputs.motion[:, ext.joint, None].astype(float)

    def candidates(self, layout, x, inputs):
        # a joint that moved only one way leaves a constant, which its offset already is
        d = inputs.motion
        return [
            Extension(self.name, joint=j)
            for j in range(layout.robot.n_joints)
            if (d[:, j] > 0).any() and (d[:, j] < 0).any()
        ]

    def parameters(self, ext, basis):
        return {"backlash_deg": float(-np.degrees(ext.coef[0]))}

    def evidence(self, ext, p, gain):
        b = p["backlash_deg"] * 1000
        how = "lags behind" if b >= 0 else "runs ahead of"
        return (
            f"Joint {ext.joint + 1}'s residual rotation flips by {2 * abs(b):.1f} mdeg with the "
            f"direction of its last motion (it {how} its motion by {abs(b):.1f} mdeg: backlash); "
            f"{gain}."
        )

    def figure(self, ext, inputs, expected):
        j, m = ext.joint + 1, len(inputs.q)
        spread = 0.3 * (np.arange(m) / max(m - 1, 1) - 0.5)  # the poses side by side, in file order
        return {
            "x": inputs.motion[:, ext.joint] + spread,
            "x_label": f"direction of joint {j}'s last motion (spread by pose)",
            "y_label": f"joint {j} error / mdeg",
        }


class PointEffect(Effect):
    """An effect that moves the predicted SMR centres after the kinematics, once per model."""

    is_joint, once = False, True

    def candidates(self, layout, x, inputs):
        return []

    def origin(self, ext, layout, x) -> np.ndarray:
        """The point the displacement is taken about."""
        return ext.origin

    def shift(self, ext, s, v, coef):
        """Displacement (N, 3) of points at v from the origin, switched or scaled by s (N,), and
        its Jacobian (P, N, 3)."""
        raise NotImplementedError

    def figure(self, ext, inputs, expected):
        raise NotImplementedError


class ThermalDrift(PointEffect):
    """SMR positions scale about the robot base by kappa (T - T_ref), T the air (else the time)."""

    name = "thermal_drift"
    stored = (("t_ref", "number"), ("variable", "string"))
    VARIABLES = ("temp_c", "time_s")

    def basis(self, ext, layout, x, inputs):
        return getattr(inputs, ext.variable) - ext.t_ref

    def candidates(self, layout, x, inputs):
        # a variable some pose lacks altogether leaves that pose's growth undefined
        t = inputs.temp_c
        if t is not None and np.isfinite(t).all() and np.ptp(t) >= THERMAL_MIN_SPAN_C:
            return [Extension(self.name, variable="temp_c", t_ref=float(np.mean(t)))]
        if inputs.time_s is not None and np.isfinite(inputs.time_s).all():
            return [Extension(self.name, variable="time_s", t_ref=float(np.mean(inputs.time_s)))]
        return []

    def needs(self, ext):
        return ext.variable

    def from_json(self, read):
        out = super().from_json(read)
        if out["variable"] not in self.VARIABLES:
            raise read.error("variable", f"expected one of {', '.join(self.VARIABLES)}")
        return out

    def origin(self, ext, layout, x):
        return layout.base(x)[:3, 3]

    def shift(self, ext, s, v, coef):
        J = (s[:, None] * v)[None]
        return coef[0] * J[0], J

    def parameters(self, ext, basis):
        per_c = ext.variable == "temp_c"
        unit = "ppm_per_c" if per_c else "ppm_per_hour"
        return {
            f"growth_{unit}": float(ext.coef[0] * (1e6 if per_c else 1e6 * 3600.0)),
            "variable": ext.variable,
            "reference": ext.t_ref,
        }

    def evidence(self, ext, p, gain):
        key = next(k for k in p if k.startswith("growth_"))
        unit = "ppm per degC" if ext.variable == "temp_c" else "ppm per hour"
        return f"SMR distances from the robot base grow {p[key]:.1f} {unit} with {ext.variable}; {gain}."

    def figure(self, ext, inputs, expected):
        per_c = ext.variable == "temp_c"
        return {
            "x": np.nanmean(getattr(inputs, ext.variable), axis=1),
            "x_label": "air temperature / degC" if per_c else "time / s",
            "y_label": "radial growth / ppm",
        }

    def signature_axis(self, ext, Jq, p, layout, x):
        return p - layout.base(x)[:3, 3], 1e6


class BaseShift(PointEffect):
    """A rigid displacement (translation, small rotation about the data's centroid) after at_s."""

    name, params, located_in_time = "base_shift", 6, True
    stored, report_keys = (("at_s", "number"), ("origin", "vector")), ("at_s",)

    def label(self, ext):
        return self.name if ext.at_s is None else f"{self.name}(t={ext.at_s:.0f}s)"

    def basis(self, ext, layout, x, inputs):
        return (inputs.time_s >= ext.at_s).astype(float)

    def candidates(self, layout, x, inputs):
        t = inputs.time_s
        return [Extension(self.name)] if t is not None and np.isfinite(t).any() else []

    def needs(self, ext):
        return "time_s"

    def shift(self, ext, s, v, coef):
        J = np.zeros((6, len(v), 3))
        for a in range(3):
            J[a, :, a] = s
            e = np.zeros(3)
            e[a] = 1.0
            J[3 + a] = s[:, None] * np.cross(e, v)
        return np.einsum("pnc,p->nc", J, coef), J

    def parameters(self, ext, basis):
        c = np.asarray(ext.coef, dtype=float)
        return {
            "at_s": ext.at_s,
            "translation_mm": np.round(c[:3], 5).tolist(),
            "rotation_deg": np.round(np.degrees(c[3:]), 6).tolist(),
            "shift_mm": float(np.linalg.norm(c[:3])),
        }

    def evidence(self, ext, p, gain):
        return (
            f"Readings after t = {ext.at_s:.0f} s are displaced by {p['shift_mm']:.3f} mm "
            f"as a rigid body; {gain}."
        )

    def figure(self, ext, inputs, expected):
        return {
            "x": np.nanmean(inputs.time_s, axis=1),
            "x_label": "time / s",
            "y_label": "displacement along the shift / mm",
        }

    def signature_axis(self, ext, Jq, p, layout, x):
        u = ext.coef[:3] / max(np.linalg.norm(ext.coef[:3]), 1e-12)
        return np.broadcast_to(u, p.shape), 1.0


KINDS: dict[str, Effect] = {
    k.name: k
    for k in (
        JointPeriodic(),
        JointScale(),
        JointCompliance(),
        JointBacklash(),
        ThermalDrift(),
        BaseShift(),
    )
}


def after_campaign(extensions) -> float | None:
    """A time (s) on the campaign's clock past everything the extensions locate in it, for data
    measured after the campaign, where their only clock is a base shift's: the cell then stands as
    the campaign left it (moved). None where another extension needs the time itself. A later
    file's time_s counts from its own start, not the campaign's: it says nothing of that."""
    timed = [e for e in extensions if e.kind.needs(e) == "time_s"]
    if not timed or any(e.name != BaseShift.name for e in timed):
        return None
    return max(float(e.at_s) for e in timed) + 1.0


def missing_input(extensions, inputs: Inputs, pose_ids=None) -> str | None:
    """Why the extensions cannot predict these inputs (a column they need absent, or blank on a
    pose), in a sentence naming the first such pose; None when they can."""
    for e in extensions:
        need = e.kind.needs(e)
        if not need:
            continue
        have = getattr(inputs, need)
        if have is None:
            return f"the model's {e.label()} needs a {need} column in the poses"
        lacking = np.flatnonzero(~np.isfinite(have).all(axis=1))
        if len(lacking):
            k = int(lacking[0])
            pose = repr(pose_ids[k]) if pose_ids is not None else f"number {k + 1}"
            return (
                f"pose {pose} has no {need} (a blank field), which the model's {e.label()} "
                f"needs ({len(lacking)} such pose{'s' if len(lacking) > 1 else ''})"
            )
    return None


def candidates(layout, x, inputs: Inputs) -> list[Extension]:
    """Every effect of the vocabulary that this data could show, per joint and harmonic."""
    return [c for kind in KINDS.values() for c in kind.candidates(layout, x, inputs)]
