"""The virtual cell: a true arm unlike its nominal model, SMRs on its flange, a laser tracker."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Protocol

import numpy as np

from robocal.solver.kinematics import Layout, flange_frames, rot, translation
from robocal.solver.measurements import Measurements
from robocal.solver.robot import Robot

LIMIT_MARGIN_RAD = np.deg2rad(2.0)


def limit_margin(robot) -> np.ndarray:
    """Per joint (rad), how far drawn poses keep from the limits: LIMIT_MARGIN_RAD, or a quarter
    of the range of a joint narrower than four of it (a locked joint's +-0.5 deg)."""
    return np.minimum(LIMIT_MARGIN_RAD, 0.25 * (robot.upper - robot.lower))


MIN_RANGE_MM = 1000.0  # trackers are specified from about 1 m; closer, the head cannot follow
AXIS_CLEARANCE_MM = 300.0  # flange near the base z axis: the shoulder singularity
WRIST_MIN_RAD = np.deg2rad(10.0)  # axes of joints N-2 and N nearly aligned: the wrist singularity
MOVE_S, PAUSE_S, TARGET_GAP_S = 8.0, 10.0, 2.0  # the seed paper's cycle: move, pause 10 s, measure
TEMP_NOISE_C = 0.02
OUTLIER_MM = (0.3, 2.0)  # a mis-lock or a bumped SMR: a reading this far off, in any direction
EXTRAS_STREAM = 0xCA4B  # scatter, absent SMRs and outliers draw from their own stream per seed


# What to change when a pose check passes too rarely: named in the refusal, per check.
CHECK_FIXES = {
    "limits": "widen the joint limits",
    "floor": "keep the SMRs above the floor: check the link lengths (mm) and the targets",
    "facing": "turn the SMRs towards the tracker: check the targets and the base guess",
    "range": "move the tracker at least 1 m from every SMR: check the base guess",
    "base_axis": "keep the flange 300 mm off the base's z axis: check the link lengths (mm)",
    "wrist": "keep the wrist off its singularity: check the last joints' twists (alpha)",
    "bounds": "widen the bounds",
}


class PosesTooConstrained(ValueError):
    """Too few random poses meet the pose checks; the message names the check to relax."""


def too_constrained(
    n: int, found: int, drawn: int, passed: dict[str, int], cell: VirtualCell | None = None, q=None
) -> PosesTooConstrained:
    """The refusal of a draw that found `found` of `n` poses: each check's pass rate, and what
    to change for the checks that pass least (under 1%, else the rarest); with the cell and
    poses q drawn, what ruled out the SMRs' facing (VirtualCell.facing_said)."""
    rates = {k: v / drawn for k, v in passed.items()}
    worst = [k for k, r in rates.items() if r < 0.01] or [min(rates, key=lambda k: rates[k])]
    said = {"facing": cell.facing_said(q)} if cell is not None and q is not None else {}
    fixes = "; ".join(
        f"{k}: " + (f"{said[k]}: " if said.get(k) else "") + CHECK_FIXES.get(k, "relax it")
        for k in worst
    )
    fewer = " or ask for fewer poses," if found else ""
    shown = ", ".join(f"{k} {r:.1%}" for k, r in rates.items())
    return PosesTooConstrained(
        f"constraints too tight: only {found} of {n} poses valid after {drawn} draws (pass "
        f"rate per check: {shown}):{fewer} {fixes}"
    )


@dataclass(frozen=True)
class TrackerSpec:
    """Tracker accuracy as a maximum permissible error MPE = mpe_um + mpe_um_per_m * range."""

    mpe_um: float = 10.0
    mpe_um_per_m: float = 2.5

    @classmethod
    def of(cls, tracker: dict) -> TrackerSpec:
        """The spec of a cell's tracker block, whose traceability keys (serial, its calibration
        certificate, SMR ids) say nothing of its accuracy."""
        return cls(**{k: float(tracker[k]) for k in ("mpe_um", "mpe_um_per_m") if k in tracker})

    def sigma_mm(self, distance_mm):
        """Per-axis standard deviation (mm) of a reading at that range: MPE / 2."""
        return 0.5e-3 * (self.mpe_um + self.mpe_um_per_m * np.asarray(distance_mm) / 1000.0)


@dataclass(frozen=True)
class GeometricErrors:
    """Standard deviations of the manufacturing errors (mm, degrees)."""

    length_mm: float = 0.5
    theta_deg: float = 0.05
    alpha_deg: float = 0.03
    beta_deg: float = 0.03
    smr_mm: float = 1.0  # per coordinate: the fixture drawing is a few mm off

    def sigmas(self, param_names) -> np.ndarray:
        """Standard deviations (mm, rad) in the order of `Robot.param_names`."""
        by_kind = {
            "a": self.length_mm,
            "d": self.length_mm,
            "theta": np.deg2rad(self.theta_deg),
            "alpha": np.deg2rad(self.alpha_deg),
            "beta": np.deg2rad(self.beta_deg),
        }
        return np.array([by_kind[n.rstrip("0123456789")] for n in param_names])


class Effect(Protocol):
    """Switchable physics beyond geometry; each method returns None when it contributes nothing.

    `time_s` and `temp_c` are per pose (m,) or None when unknown. Optional extras that
    `campaign` honours: a `temperature_rise_c` attribute (the air warms by that much over the
    campaign) and a `start_campaign(cell, time_s, temp_c)` method, called with the readings'
    (m, K) times and true air temperatures before they are measured.
    """

    def joint_offsets(self, cell: VirtualCell, q, time_s, temp_c):
        """Joint-angle errors dq (m, N) rad added to the readings q, or None."""

    def base_motion(self, cell: VirtualCell, time_s, temp_c):
        """Per-pose maps (m, 4, 4) applied to base-frame points before the base, or None.

        Usually rigid motions of the base; thermal growth returns a scaling diag(s, s, s, 1).
        """


@dataclass
class VirtualCell:
    """Simulated hardware: the true robot and SMRs, the tracker placement, its noise and effects."""

    nominal_robot: Robot
    true_robot: Robot
    target_names: tuple[str, ...]
    nominal_targets: np.ndarray  # (K, 3) mm in the flange frame
    true_targets: np.ndarray
    base: np.ndarray  # 4x4 base-in-tracker
    tracker: TrackerSpec = TrackerSpec()
    acceptance_rad: float = np.deg2rad(60.0)  # SMR half-angle; an SMR faces along flange z
    floor_clearance_mm: float = 150.0
    effects: list = field(default_factory=list)
    seed: int | None = None
    last_campaign: dict | None = None
    # gravity's direction in the base frame: a floor-mounted arm's -z unless the cell's base (a
    # wall or ceiling mount seen from a levelled tracker) says otherwise
    down: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -1.0]))

    @classmethod
    def random(
        cls,
        robot: Robot,
        targets: dict,
        seed: int,
        errors: GeometricErrors = GeometricErrors(),
        tracker: TrackerSpec = TrackerSpec(),
        acceptance_rad: float = np.deg2rad(60.0),
        floor_clearance_mm: float = 150.0,
        effects=(),
        base=None,
    ) -> VirtualCell:
        """A cell whose true geometry, SMR positions and tracker placement are drawn from `seed`;
        `base` (the cell's 4x4 base in the tracker frame, a levelled tracker) places the arm
        instead, mounted on a wall or a ceiling as its rotation says."""
        rng = np.random.default_rng(seed)
        names = tuple(targets)
        nominal_t = np.array([targets[n] for n in names], dtype=float).reshape(len(names), 3)
        p0 = robot.param_vector()
        p_true = p0 + errors.sigmas(robot.param_names()) * rng.normal(size=p0.size)
        true_t = nominal_t + rng.normal(scale=errors.smr_mm, size=nominal_t.shape)
        placement = random_tracker_placement(rng)  # drawn always: the seed's other draws stay
        down = np.array([0.0, 0.0, -1.0])
        if base is not None:
            placement = np.asarray(base, dtype=float)
            down = placement[:3, :3].T @ down  # the tracker's -z, levelled, in the base frame
        return cls(
            robot,
            robot.with_params(p_true),
            names,
            nominal_t,
            true_t,
            placement,
            tracker,
            acceptance_rad,
            floor_clearance_mm,
            list(effects),
            seed,
            down=down,
        )

    def _points(self, q, dq=None, motion=None, record=False):
        """SMR centres in the tracker frame; in the base frame SMRs, flange R and o; joint axes."""
        lay = Layout(self.true_robot, np.eye(4), self.target_names)
        R, o, *rec = flange_frames(lay, lay.initial(self.true_targets), q, dq, record)
        p = np.einsum("mij,kj->mki", R, self.true_targets) + o[:, None, :]
        to_tracker = self.base if motion is None else self.base @ motion
        to_tracker = np.broadcast_to(to_tracker, (len(p), 4, 4))
        pt = np.einsum("mij,mkj->mki", to_tracker[:, :3, :3], p) + to_tracker[:, None, :3, 3]
        return pt, p, R, o, (rec[0] if rec else None)

    def pose_checks(self, q) -> dict[str, np.ndarray]:
        """Per constraint, which poses (m,) satisfy it; static true geometry, effects ignored."""
        q = np.atleast_2d(q)
        pt, p, R, o, rec = self._points(q, record=True)
        dist = np.linalg.norm(pt, axis=-1)
        normal = np.einsum("ij,mj->mi", self.base[:3, :3], R[:, :, 2])  # flange z in tracker frame
        facing = np.einsum("mj,mkj->mk", normal, -pt) / dist  # tracker sits at its frame's origin
        checks = {
            "limits": self.true_robot.within_limits(q, limit_margin(self.true_robot)),
            "floor": np.all(p[..., 2] >= self.floor_clearance_mm, axis=1),
            "facing": np.all(facing >= np.cos(self.acceptance_rad), axis=1),
            "range": np.all(dist >= MIN_RANGE_MM, axis=1),
            "base_axis": np.hypot(o[:, 0], o[:, 1]) >= AXIS_CLEARANCE_MM,
        }
        n = q.shape[1]
        if n >= 6:  # spherical-wrist arms: singular when the axes of joints N-2 and N align
            axes = [axis for op, axis, _ in rec if op.kind == "r" and op.joint >= 0]
            cross = np.linalg.norm(np.cross(axes[n - 3], axes[n - 1]), axis=-1)
            checks["wrist"] = cross >= np.sin(WRIST_MIN_RAD)
        return checks

    def facing_said(self, q) -> str:
        """What kept the SMRs from facing the tracker in poses q (m, N) rad: the best angle any
        pose gives, and the one direction the normal keeps when the arm cannot turn it."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        pt, _, R, _, _ = self._points(q)
        normal = np.einsum("ij,mj->mi", self.base[:3, :3], R[:, :, 2])  # tracker frame
        cos = np.einsum("mj,mkj->mk", normal, -pt) / np.linalg.norm(pt, axis=-1)
        best = np.degrees(np.arccos(np.clip(cos.min(axis=1).max(), -1.0, 1.0)))
        said = (
            f"the SMRs face along the flange's z axis, at best {best:.0f} deg from the tracker "
            f"in {len(q)} poses drawn ({np.degrees(self.acceptance_rad):.0f} deg accepted)"
        )
        z = R[:, :, 2]  # the base frame
        mean = z.mean(axis=0)
        if np.linalg.norm(mean) < 1e-9:
            return said
        mean /= np.linalg.norm(mean)
        spread = np.degrees(np.arccos(np.clip(z @ mean, -1.0, 1.0))).max()
        if spread >= 90.0:
            return said
        way = {1: "up (the base's +z)", -1: "down (the base's -z)"}.get(
            int(np.sign(mean[2])) if abs(mean[2]) > 0.9 else 0,
            "(" + ", ".join(f"{v:+.2f}" for v in mean) + ") in the base frame",
        )
        return f"{said}: in every one they face within {spread:.0f} deg of {way}"

    def sample_poses(self, n: int, rng, max_batches: int = 50) -> np.ndarray:
        """n poses (n, N) rad drawn uniformly within the limits and meeting every pose check."""
        margin = limit_margin(self.true_robot)
        lo, hi = self.true_robot.lower + margin, self.true_robot.upper - margin
        batch = max(1024, 4 * n)
        found: list[np.ndarray] = []
        passed: dict[str, int] = {}
        for _ in range(max_batches):
            q = rng.uniform(lo, hi, size=(batch, lo.size))
            checks = self.pose_checks(q)
            for name, ok in checks.items():
                passed[name] = passed.get(name, 0) + int(ok.sum())
            found.append(q[np.logical_and.reduce(list(checks.values()))])
            if sum(len(f) for f in found) >= n:
                return np.concatenate(found)[:n]
        raise too_constrained(n, sum(len(f) for f in found), max_batches * batch, passed, self, q)

    def true_points(self, q, time_s=None, temp_c=None, pose_dq=None) -> np.ndarray:
        """Noise-free SMR centres (m, K, 3) in the tracker frame, with every effect applied.

        time_s and temp_c may be per pose (m,) or per reading (m, K); pose_dq (m, N) rad is a
        joint error the arm makes at each pose beyond what any effect predicts (its scatter).
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        m, K = q.shape[0], len(self.target_names)
        if not self.effects:
            return self._points(q, pose_dq)[0]

        def per_reading(a):  # (m,) or (m, K) -> (m, K)
            return None if a is None else np.broadcast_to(np.reshape(a, (m, -1)), (m, K))

        t, c = per_reading(time_s), per_reading(temp_c)
        out = np.empty((m, K, 3))
        for k in range(K):  # each reading is taken at its own time and temperature
            tk, ck = (None if t is None else t[:, k]), (None if c is None else c[:, k])
            dq, motion = pose_dq, np.broadcast_to(np.eye(4), (m, 4, 4))
            for effect in self.effects:
                d = effect.joint_offsets(self, q, tk, ck)
                if d is not None:
                    dq = d if dq is None else dq + d
                b = effect.base_motion(self, tk, ck)
                if b is not None:
                    motion = motion @ b
            out[:, k] = self._points(q, dq, motion)[0][:, k]
        return out

    def measure(
        self, q, rng, time_s=None, temp_c=None, pose_dq=None, noise_scale: float = 1.0
    ) -> np.ndarray:
        """Tracker readings (m, K, 3): true points plus Gaussian noise, noise_scale x the spec."""
        p = self.true_points(q, time_s, temp_c, pose_dq)
        sigma = noise_scale * self.tracker.sigma_mm(np.linalg.norm(p, axis=-1))
        return p + sigma[..., None] * rng.normal(size=p.shape)

    def noise_floor_mm(self, q, noise_scale: float = 1.0) -> float:
        """Expected 3-D RMS of the tracker noise (noise_scale x spec) over these poses' readings."""
        sigma = self.tracker.sigma_mm(np.linalg.norm(self._points(np.atleast_2d(q))[0], axis=-1))
        return float(noise_scale * np.sqrt(np.mean(3 * sigma**2)))

    def campaign(
        self,
        n_poses: int,
        seed: int,
        beam_break_rate: float = 0.0,
        arm_scatter_deg: float = 0.0,
        targets_per_pose: int | None = None,
        outlier_rate: float = 0.0,
        noise_scale: float = 1.0,
        poses=None,
    ) -> Measurements:
        """A measured campaign of n_poses random poses (or these poses (n_poses, N) rad, in this
        order), timed and with the air temperature.

        Beyond the tracker's noise (noise_scale x its spec) and beam breaks, a campaign may have
        the arm's own scatter (a joint error drawn afresh per pose, std arm_scatter_deg per joint,
        shared by every SMR of the pose), only targets_per_pose random SMRs measured per pose,
        and a fraction outlier_rate of the readings displaced 0.3-2 mm (listed in the truth).
        """
        rng = np.random.default_rng(seed)
        extra = np.random.default_rng([EXTRAS_STREAM, seed])  # rng's draws stay as they were
        if poses is None:
            q = self.sample_poses(n_poses, rng)
        else:
            q = np.array(poses, dtype=float).reshape(n_poses, self.true_robot.n_joints)
        K = len(self.target_names)
        moves = rng.uniform(MOVE_S - 2, MOVE_S + 2, n_poses)
        arrive = np.cumsum(moves) + PAUSE_S * np.arange(n_poses)
        time_s = (
            arrive[:, None] + 1.0 + TARGET_GAP_S * np.arange(K) + rng.uniform(0, 0.5, (n_poses, K))
        )
        # air: a slow drift of a few tenths of a degree over the campaign; the sensor adds noise
        drift = rng.uniform(0.2, 0.5) * rng.choice([-1.0, 1.0])
        air = rng.normal(20.0, 0.3) + drift * time_s / time_s.max()
        rise = sum(getattr(e, "temperature_rise_c", 0.0) for e in self.effects)
        if rise:  # effects that need a warming cell: a warm-up curve, steeper at the start
            air = air + rise * np.expm1(-2.0 * time_s / time_s.max()) / np.expm1(-2.0)
        temp_c = air + rng.normal(scale=TEMP_NOISE_C, size=air.shape)
        for effect in self.effects:
            if hasattr(effect, "start_campaign"):
                effect.start_campaign(self, time_s, air)
        pose_dq = None
        if arm_scatter_deg > 0:
            pose_dq = np.deg2rad(arm_scatter_deg) * extra.normal(size=q.shape)
        xyz = self.measure(q, rng, time_s, air, pose_dq, noise_scale)
        broken = rng.random((n_poses, K)) < beam_break_rate
        if targets_per_pose is not None and targets_per_pose < K:
            keep = np.argsort(extra.random((n_poses, K)), axis=1)[:, :targets_per_pose]
            absent = np.ones((n_poses, K), dtype=bool)
            np.put_along_axis(absent, keep, False, axis=1)
            broken |= absent
        outliers = self._displace(xyz, ~broken, outlier_rate, extra) if outlier_rate > 0 else []
        xyz[broken], time_s[broken], temp_c[broken] = np.nan, np.nan, np.nan
        self.last_campaign = {
            "seed": seed,
            "n_poses": n_poses,
            "beam_break_rate": beam_break_rate,
            "noise_floor_mm": self.noise_floor_mm(q, noise_scale),
        }
        self.last_campaign.update(
            arm_scatter_deg=arm_scatter_deg,
            targets_per_pose=targets_per_pose,
            outlier_rate=outlier_rate,
            noise_scale=noise_scale,
            outliers=outliers,
        )
        if pose_dq is not None:  # how far the scatter moves the SMRs: part of any model's floor
            moved = self._points(q, pose_dq)[0] - self._points(q)[0]
            self.last_campaign["arm_scatter_rms_mm"] = float(np.sqrt(np.mean(np.sum(moved**2, -1))))
        return Measurements(
            [str(i) for i in range(1, n_poses + 1)], q, self.target_names, xyz, time_s, temp_c
        )

    def _displace(self, xyz, present, rate: float, rng) -> list[dict]:
        """Move round(rate x present readings), at least one, 0.3-2 mm in random directions."""
        idx = np.argwhere(present)
        count = min(len(idx), max(1, round(rate * len(idx))))
        out = []
        for i, k in idx[np.sort(rng.choice(len(idx), count, replace=False))]:
            direction = rng.normal(size=3)
            offset = rng.uniform(*OUTLIER_MM) * direction / np.linalg.norm(direction)
            xyz[i, k] += offset
            out.append(
                {
                    "pose": str(i + 1),
                    "target": self.target_names[k],
                    "displacement_mm": float(np.linalg.norm(offset)),
                    "offset_mm": [float(v) for v in offset],
                }
            )
        return out

    def truth(self) -> dict:
        """The hidden truth, JSON-serialisable: lengths in mm, angles in degrees."""

        def params(robot):
            return {
                n: float(np.rad2deg(v) if n.startswith(("theta", "alpha", "beta")) else v)
                for n, v in zip(robot.param_names(), robot.param_vector())
            }

        def targets(t):
            return {n: [float(v) for v in row] for n, row in zip(self.target_names, t)}

        last = self.last_campaign or {}
        return {
            "seed": self.seed,
            "robot": self.nominal_robot.name,
            "convention": self.nominal_robot.convention,
            "true_params": params(self.true_robot),
            "nominal_params": params(self.nominal_robot),
            "true_targets": targets(self.true_targets),
            "nominal_targets": targets(self.nominal_targets),
            "base": self.base.tolist(),
            "gravity_in_base": self.down.tolist(),
            "tracker": asdict(self.tracker),
            "acceptance_deg": float(np.rad2deg(self.acceptance_rad)),
            "floor_clearance_mm": float(self.floor_clearance_mm),
            "effects": [
                e.describe() if hasattr(e, "describe") else {"name": type(e).__name__}
                for e in self.effects
            ],
            "campaign": last or None,
            "noise_floor_mm": last.get("noise_floor_mm"),
        }


def random_tracker_placement(rng) -> np.ndarray:
    """Base-in-tracker 4x4 for a level tracker 2.5-4.5 m in front of the robot, with random yaw."""
    r, az = rng.uniform(2500.0, 4500.0), rng.uniform(-np.pi / 3, np.pi / 3)
    h, yaw = rng.uniform(300.0, 1200.0), rng.uniform(-np.pi, np.pi)
    tilt, tilt_dir = rng.uniform(0.0, np.deg2rad(0.1)), rng.uniform(-np.pi, np.pi)
    # tilting about a horizontal axis at tilt_dir leaves z exactly `tilt` off vertical
    level = rot(2, tilt_dir) @ rot(0, tilt) @ rot(2, -tilt_dir)
    tracker_in_base = translation(r * np.cos(az), r * np.sin(az), h) @ rot(2, yaw) @ level
    return np.linalg.inv(tracker_in_base)


def displace(xyz, seed, rate):
    """Readings (m, K, 3) with a share `rate` of the present ones moved 0.3-2 mm (OUTLIER_MM) in random
    directions (drawn from seed), and the mask (m, K) of those moved."""
    rng = np.random.default_rng([7, seed])
    have = np.argwhere(np.all(np.isfinite(xyz), axis=-1))
    pick = have[rng.choice(len(have), max(1, int(round(rate * len(have)))), replace=False)]
    out, moved = xyz.copy(), np.zeros(xyz.shape[:2], dtype=bool)
    for p, k in pick:
        v = rng.normal(size=3)
        out[p, k] += rng.uniform(*OUTLIER_MM) * v / np.linalg.norm(v)
        moved[p, k] = True
    return out, moved
