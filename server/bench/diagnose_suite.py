"""A harder simulated suite for `diagnose` (issue 10): cases drawn from seeds, and their scoring.

A case is a virtual cell (robot, SMR layout, hidden geometry), the effect specs hidden in it with
magnitudes aimed from the seed, and the campaign's options (size, tracker noise, arm scatter, one
SMR a pose, missing readings, gross outliers). Everything is reproducible through the command line:
`robocal simulate --seed CELL_SEED --effect SPEC ... ` with `Case.simulate_args()`.

Magnitudes are drawn so that the effect is plainly visible in principle: a geometric-only fit's
held-out error on a large noise-free probe campaign, combined with the case's own floor (tracker
noise and arm scatter), is a drawn multiple (2x-5x) of that floor. They are never tuned to what
the diagnosis finds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.drivers.cell import TrackerSpec, VirtualCell
from robocal.drivers.effects import EFFECTS, make_effects
from robocal.server.formats.cell_json import Cell, default_cell
from robocal.server.formats.report_doc import ReportDoc
from robocal.solver.robot import KUKA_LIKE, Robot, robot_from_degrees

SUITE_STREAM = 0x5017E
SIZES = (30, 40, 60, 100)
NOISE_SCALE = (1.0, 6.0)  # tracker noise, multiples of its spec
SCATTER_DEG = (0.002, 0.006)  # the arm's per-pose joint error, std per joint
OUTLIER_RATE = (0.01, 0.03)
MISSING_RATE = 0.10
MULTIPLE = (2.0, 5.0)  # geometric-only held-out error over the floor, with the effect alone
PROBE_POSES, PROBE_FIT = 150, 100
COMPLIANCE_JOINTS = (2, 3)  # the shoulder and elbow carry the largest gravity torques on a 6R arm
OOV = "joint_coupling:5"  # dq5 = c q4: a wrist coupling outside the vocabulary
# (kind, effect specs without magnitude); "J" a random joint, "G" joint 2 or 3, "H" harmonic 1 or 2
KINDS = {
    "clean": (),
    "joint_compliance": ("joint_compliance:G",),
    "joint_periodic": ("joint_periodic:J:H",),
    "joint_scale": ("joint_scale:J",),
    "thermal_drift": ("thermal_drift",),
    "base_shift": ("base_shift",),
    "joint_backlash": ("joint_backlash:J",),
    "compliance_2_3": ("joint_compliance:2", "joint_compliance:3"),
    "compliance_periodic": ("joint_compliance:G", "joint_periodic:J:H"),
    "out_of_vocabulary": (OOV,),
}


@dataclass
class Case:
    """One drawn campaign: the cell, its hidden effects and the campaign's options."""

    seed: int
    kind: str
    robot: Robot
    targets: dict  # name -> (3,) mm in the flange frame
    cell_seed: int  # the cell's geometry, effects and campaign: `robocal simulate --seed`
    n_poses: int
    options: dict  # VirtualCell.campaign keyword arguments beyond the size
    specs: tuple = ()  # effect specs with their aimed magnitudes
    hidden: list = field(default_factory=list)  # (name, joint from 1 or None, harmonic or None)
    multiples: list = field(default_factory=list)  # drawn geometric-only error / floor, per effect
    skip: str | None = None  # why the case cannot run here (an effect not in the vocabulary yet)

    @property
    def out_of_vocabulary(self) -> bool:
        return self.kind == "out_of_vocabulary"

    def cell(self) -> VirtualCell:
        """The virtual cell, with the hidden effects, exactly as `robocal simulate` builds it."""
        return virtual_cell(self.robot, self.targets, self.cell_seed, self.specs)

    def simulate_args(self) -> list[str]:
        """`robocal simulate` arguments (without --cell, --out) for the same campaign."""
        args = ["--poses", str(self.n_poses), "--seed", str(self.cell_seed)]
        for key, value in self.options.items():
            if value is not None:
                args += ["--" + key.replace("_", "-"), f"{value:.6g}"]
        for s in self.specs:
            args += ["--effect", s]
        return args

    def describe(self) -> dict:
        return {
            "seed": self.seed,
            "kind": self.kind,
            "robot": self.robot.name,
            "targets": len(self.targets),
            "poses": self.n_poses,
            "cell_seed": self.cell_seed,
            "options": self.options,
            "effects": list(self.specs),
            "multiples": [round(m, 2) for m in self.multiples],
            "skip": self.skip,
        }


def virtual_cell(robot: Robot, targets: dict, cell_seed: int, specs) -> VirtualCell:
    """The virtual cell of a case with its hidden effects, as `robocal simulate` builds it."""
    vc = VirtualCell.random(
        robot, targets, seed=cell_seed, tracker=TrackerSpec.of(Cell(robot, targets).tracker)
    )
    vc.effects.extend(make_effects(specs, vc, cell_seed))
    return vc


def random_arm(rng, name: str) -> Robot:
    """A plausible 6R industrial arm in standard DH: vertical base axis, parallel 2 and 3, wrist."""
    return robot_from_degrees(
        name,
        "dh",
        [
            (rng.uniform(0, 350), rng.uniform(350, 800), 0.0, -90.0, (-180.0, 180.0)),
            (
                rng.uniform(500, 1100),
                0.0,
                -90.0,
                0.0,
                (-rng.uniform(60, 95), rng.uniform(130, 155)),
            ),
            (rng.uniform(0, 200), 0.0, 0.0, -90.0, (-180.0, rng.uniform(60, 75))),
            (0.0, rng.uniform(500, 1200), 0.0, 90.0, (-350.0, 350.0)),
            (0.0, 0.0, 0.0, -90.0, (-rng.uniform(115, 130), rng.uniform(115, 130))),
            (0.0, rng.uniform(80, 250), 0.0, 0.0, (-350.0, 350.0)),
        ],
    )


def ur_arm(rng, name: str) -> Robot:
    """A Universal-Robots-like arm (standard DH, UR5 to UR10 sizes): parallel axes 2, 3 and 4,
    an offset wrist, every joint +-360 deg; a geometry unlike the industrial arms above."""
    s = rng.uniform(0.75, 1.45)
    return robot_from_degrees(
        name,
        "dh",
        [
            (0.0, 89.2 * s * rng.uniform(0.9, 1.1), 0.0, 90.0, (-360.0, 360.0)),
            (-425.0 * s, 0.0, 0.0, 0.0, (-360.0, 360.0)),
            (-392.0 * s, 0.0, 0.0, 0.0, (-360.0, 360.0)),
            (0.0, 109.0 * s, 0.0, 90.0, (-360.0, 360.0)),
            (0.0, 94.6 * s, 0.0, -90.0, (-360.0, 360.0)),
            (0.0, 82.3 * s, 0.0, 0.0, (-360.0, 360.0)),
        ],
    )


def smr_ring(rng) -> dict:
    """1-4 SMRs on a ring of radius 40-120 mm about the flange axis, 20-60 mm out."""
    k = int(rng.integers(1, 5))
    r, z = rng.uniform(40, 120), rng.uniform(20, 60)
    angle = rng.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(k) / k + rng.uniform(-0.2, 0.2, k)
    return {
        chr(ord("A") + i): np.array([r * np.cos(a), r * np.sin(a), z]) for i, a in enumerate(angle)
    }


def _robot_and_targets(rng, seed: int):
    which = rng.choice(["irb2600", "kuka-like", "random"], p=[0.4, 0.3, 0.3])
    irb = default_cell()
    robot = {"irb2600": irb.robot, "kuka-like": KUKA_LIKE}.get(which)
    robot = robot or random_arm(rng, f"random-6r-{seed}")
    targets = dict(irb.targets) if which == "irb2600" and rng.random() < 0.5 else smr_ring(rng)
    return robot, targets


def _options(rng, n_poses: int, n_targets: int) -> dict:
    """Campaign options; one SMR a pose only where there are poses enough to identify the arm."""
    opts = {"noise_scale": float(np.exp(rng.uniform(*np.log(NOISE_SCALE))))}
    if rng.random() < 0.4:
        opts["arm_scatter_deg"] = float(rng.uniform(*SCATTER_DEG))
    if n_targets > 1 and n_poses >= 60 and rng.random() < 0.4:
        opts["targets_per_pose"] = 1
    if rng.random() < 0.25:
        opts["beam_break_rate"] = MISSING_RATE
    if rng.random() < 0.25:
        opts["outlier_rate"] = float(rng.uniform(*OUTLIER_RATE))
    return opts


def _concrete(template: str, rng, n_joints: int) -> str:
    """A spec template with its joint (J any, G 2 or 3) and harmonic (H) drawn."""
    name, *fields = template.split(":")
    draw = {
        "J": lambda: rng.integers(1, n_joints + 1),
        "G": lambda: rng.choice(COMPLIANCE_JOINTS),
        "H": lambda: rng.integers(1, 3),
    }
    return ":".join([name] + [str(int(draw[f]())) if f in draw else f for f in fields])


def _hidden(spec: str):
    name, *fields = spec.partition("=")[0].split(":")
    joint = int(fields[0]) if fields else None
    harmonic = int(fields[1]) if len(fields) > 1 else None
    return name, joint, harmonic


def draw_case(seed: int, kind: str, aim: bool = True) -> Case:
    """The case of this seed and kind (see KINDS); magnitudes aimed unless aim is False."""
    if kind not in KINDS:
        raise ValueError(f"unknown case kind {kind!r}; choose from {', '.join(KINDS)}")
    rng = np.random.default_rng([SUITE_STREAM, seed, list(KINDS).index(kind)])
    robot, targets = _robot_and_targets(rng, seed)
    n_poses = int(rng.choice(SIZES))
    options = _options(rng, n_poses, len(targets))
    cell_seed = int(rng.integers(0, 2**31))
    templates = [_concrete(t, rng, robot.n_joints) for t in KINDS[kind]]
    multiples = [float(np.exp(rng.uniform(*np.log(MULTIPLE)))) for _ in templates]
    case = Case(
        seed,
        kind,
        robot,
        targets,
        cell_seed,
        n_poses,
        options,
        tuple(templates),
        [_hidden(t) for t in templates if kind != "out_of_vocabulary"],
        multiples,
    )
    missing = sorted({_hidden(t)[0] for t in templates} - set(EFFECTS))
    if missing:
        case.skip = (
            f"{', '.join(missing)} not in drivers.effects.EFFECTS yet (another branch "
            f"adds it); the case runs once merged"
        )
        return case
    if aim and templates:
        case.specs = tuple(aim_magnitudes(case, templates, multiples))
    return case


def aim_magnitudes(case: Case, templates, multiples) -> list[str]:
    """Specs whose magnitudes make each effect alone `multiple` x the case's floor, held out.

    The floor is the tracker noise (at the case's scale) with the arm's scatter; the effect's own
    share comes from a noise-free probe campaign of the same cell (geometric fit on 100 random
    poses, held out on 50), where it grows linearly with the magnitude.
    """
    from robocal.solver.calibrate import calibrate
    from robocal.solver.kinematics import predict
    from robocal.solver.problem import Problem

    probe = Case(
        case.seed,
        case.kind,
        case.robot,
        case.targets,
        case.cell_seed,
        PROBE_POSES,
        {},
        tuple(templates),
    )
    vc = probe.cell()  # every effect at its default: the hidden draws are those of the final specs
    effects = list(vc.effects)
    scatter = case.options.get("arm_scatter_deg", 0.0)
    probe_seed = case.cell_seed + 1
    vc.effects = []
    meas = vc.campaign(PROBE_POSES, probe_seed, arm_scatter_deg=scatter, noise_scale=0.0)
    assert vc.last_campaign is not None  # campaign() records what it drew
    floor = np.hypot(
        vc.noise_floor_mm(meas.q, case.options.get("noise_scale", 1.0)),
        vc.last_campaign.get("arm_scatter_rms_mm", 0.0),
    )
    split = np.random.default_rng(probe_seed).permutation(PROBE_POSES)
    fit_on, held = np.sort(split[:PROBE_FIT]), np.sort(split[PROBE_FIT:])
    names = vc.target_names
    nominal = np.array([case.targets[t] for t in names])
    out = []
    for template, effect, multiple in zip(templates, effects, multiples):
        vc.effects = [effect]
        meas = vc.campaign(PROBE_POSES, probe_seed, noise_scale=0.0)
        fit = calibrate(Problem.of(case.robot, nominal, meas.subset(fit_on)), "ls-sum")
        err = predict(fit.layout, fit.x, meas.q[held]) - meas.xyz[held]
        share = float(np.sqrt(np.nanmean(np.sum(err**2, axis=-1))))
        magnitude = effect.magnitude * floor * np.sqrt(multiple**2 - 1.0) / max(share, 1e-12)
        out.append(f"{template}={magnitude:.6g}")
    return out


def suite(seeds, kinds=tuple(KINDS)) -> list[tuple[int, str]]:
    """(seed, kind) pairs taking the kinds in turn, so every kind meets every few seeds."""
    return [(s, kinds[s % len(kinds)]) for s in seeds]


def _diagnoser(case: Case, meas, xyz):
    """A Diagnoser on this data, every structurally free parameter fitted and no prior: the
    reference fits of the true structure (`diagnose()` holds what ls-sum holds and fits the
    rest under ls-sum's prior)."""
    from robocal.solver import identifiability as ident
    from robocal.solver.diagnose import Diagnoser
    from robocal.solver.effects import Inputs
    from robocal.solver.identify import register

    nominal = np.array([case.targets[t] for t in meas.target_names])
    prob, x0 = register(case.robot, nominal, meas.target_names, meas.q, xyz)
    st = ident.structural(prob.layout, x0, np.ones(prob.layout.n_params, dtype=bool))
    return Diagnoser(prob, x0, st.free, Inputs(meas.q, meas.time_s, meas.temp_c))


def true_extensions(case: Case, diag) -> list | None:
    """The hidden effects as the diagnosis's own candidates (None if any lies outside them)."""
    from robocal.solver.diagnose import candidates

    cands = candidates(diag.prob.layout, diag.x0, diag.inputs)
    out = []
    for name, joint, harmonic in case.hidden:
        match = [
            c
            for c in cands
            if c.name == name
            and (joint is None or c.joint == joint - 1)
            and (harmonic is None or c.harmonic == harmonic)
        ]
        if not match:
            return None
        out.append(match[0])
    return out if not case.out_of_vocabulary else None


def without_outliers(meas, outliers) -> np.ndarray:
    """The readings with the simulated gross outliers removed (NaN)."""
    xyz = meas.xyz.copy()
    for o in outliers:
        xyz[int(o["pose"]) - 1, meas.target_names.index(o["target"])] = np.nan
    return xyz


def named_effects(report: ReportDoc) -> list[tuple]:
    """(name, joint, harmonic) of each effect the report names."""
    return [e.key() for e in report.effects]


def is_named(hidden, named) -> bool:
    """The report names the hidden effect: same effect, joint and (periodic) harmonic."""
    name, joint, harmonic = hidden
    return any(
        n == name and (joint is None or j == joint) and (harmonic is None or h == harmonic)
        for n, j, h in named
    )


def run_case(case: Case) -> dict:
    """Simulate the case, diagnose it in process and score it."""
    import time

    from robocal.solver.diagnose import diagnose
    from robocal.solver.problem import Problem

    if case.skip:
        return {"case": case.describe(), "skipped": case.skip}
    vc = case.cell()
    meas = vc.campaign(case.n_poses, case.cell_seed, **case.options)
    assert vc.last_campaign is not None  # campaign() records what it drew
    truth = dict(vc.last_campaign)
    nominal = np.array([case.targets[t] for t in meas.target_names])
    t0 = time.perf_counter()
    d = diagnose(Problem.of(case.robot, nominal, meas))
    seconds = time.perf_counter() - t0
    return score(case, vc, meas, truth, ReportDoc.of(d), d, seconds)


def score(
    case: Case,
    vc: VirtualCell,
    meas,
    truth: dict,
    report: ReportDoc,
    diagnosis=None,
    seconds: float | None = None,
) -> dict:
    """Detection, false alarm, held-out/floor ratio and (out of vocabulary) payoff of one report.

    The achievable floor is the held-out RMS of the TRUE model structure under the same
    cross-validation, on the readings without the simulated outliers; out-of-vocabulary effects
    have no such floor, so only the ratio to the geometric model's is given there.
    """
    outliers = truth.get("outliers", [])
    diag = _diagnoser(case, meas, without_outliers(meas, outliers))
    geometric = diag.cross_validate([]).rmse
    exts = true_extensions(case, diag)
    floor = None
    if exts is not None:
        floor = diag.cross_validate(exts).rmse if exts else geometric
    named = named_effects(report)
    final = report.final.holdout_rmse_mm
    out = {
        "case": case.describe(),
        "named": [list(n) for n in named],
        "hidden": [list(h) for h in case.hidden],
        "detected": [is_named(h, named) for h in case.hidden],
        "extra": [list(n) for n in named if not any(is_named(h, [n]) for h in case.hidden)],
        "false_alarm": case.kind == "clean" and bool(named),
        # a small campaign naming an effect is resampled; its doubt said when they disagree
        "resampled": report.stability is not None,
        "in_doubt": report.stability is not None and bool(report.stability.doubt),
        "outliers": len(outliers),
        "noise_floor_mm": truth["noise_floor_mm"],
        "arm_scatter_rms_mm": truth.get("arm_scatter_rms_mm"),
        "baseline_holdout_rmse_mm": report.baseline.holdout_rmse_mm,
        "final_holdout_rmse_mm": final,
        "floor_mm": floor,
        "geometric_floor_mm": geometric,
        "ratio": None if floor is None else final / floor,
        "ratio_geometric": final / geometric,
        "seconds": seconds,
    }
    if case.out_of_vocabulary and named and diagnosis is not None:
        out["payoff"] = payoff(case, vc, diag, diagnosis)
    return out


def payoff(case: Case, vc: VirtualCell, diag, diagnosis) -> dict:
    """RMS on a separate campaign of the same cell (other poses) of the named model and of geometry.

    Both are fitted on the whole diagnosed campaign (geometry without the simulated outliers).
    """
    from robocal.solver.effects import Inputs
    from robocal.solver.extended import predict_extended

    opts = {k: v for k, v in case.options.items() if k in ("noise_scale", "arm_scatter_deg")}
    test = vc.campaign(100, case.cell_seed + 2, **opts)
    inputs = Inputs(test.q, test.time_s, test.temp_c)

    def rms(layout, x, exts):
        err = predict_extended(layout, x, exts, inputs) - test.xyz
        return float(np.sqrt(np.nanmean(np.sum(err**2, axis=-1))))

    x, _ = diag.fit([])
    named = rms(diagnosis.layout, diagnosis.x, diagnosis.extensions)
    geometric = rms(diag.prob.layout, x, [])
    return {"named_rmse_mm": named, "geometric_rmse_mm": geometric, "pays_off": named < geometric}


def doubt_rates(ran: list[dict]) -> dict:
    """How often a small campaign's resamples put its answer in doubt: on clean campaigns, and
    on effect campaigns whose hidden effects were all named or not."""

    def rate(rs):
        sampled = [r for r in rs if r.get("resampled")]
        return {"resampled": len(sampled), "in_doubt": sum(r["in_doubt"] for r in sampled)}

    effect = [r for r in ran if r["case"]["kind"] != "clean"]
    return {
        "clean": rate([r for r in ran if r["case"]["kind"] == "clean"]),
        "effect_all_named": rate([r for r in effect if all(r["detected"])]),
        "effect_missed": rate([r for r in effect if not all(r["detected"])]),
    }


def summarize(results: list[dict]) -> dict:
    """Detection per effect type and size, false alarms, ratios, out-of-vocabulary payoff."""
    ran = [r for r in results if "skipped" not in r]
    per_type: dict = {}
    per_size: dict = {}
    per_both: dict = {}
    for r in ran:
        size = str(r["case"]["poses"])
        for (name, *_), hit in zip(r["hidden"], r["detected"]):
            for table, key in ((per_type, name), (per_size, size), (per_both, f"{name}@{size}")):
                row = table.setdefault(key, {"hidden": 0, "named": 0})
                row["hidden"] += 1
                row["named"] += int(hit)
    for table in (per_type, per_size, per_both):
        for row in table.values():
            row["rate"] = row["named"] / row["hidden"]
    hidden = sum(len(r["hidden"]) for r in ran)
    clean = [r for r in ran if r["case"]["kind"] == "clean"]
    alarms = sum(r["false_alarm"] for r in clean)
    ratios = [r["ratio"] for r in ran if r["ratio"] is not None and not r["outliers"]]
    outlier_ratios = [r["ratio"] for r in ran if r["ratio"] is not None and r["outliers"]]
    oov = [r for r in ran if r["case"]["kind"] == "out_of_vocabulary"]
    unpaid = [r for r in oov if r["named"] and not r.get("payoff", {}).get("pays_off", False)]

    def stats(v):
        return {
            "count": len(v),
            "median": float(np.median(v)) if v else None,
            "worst": float(np.max(v)) if v else None,
        }

    times = [r["seconds"] for r in ran if r["seconds"] is not None]
    by_size = {
        str(n): stats([r["seconds"] for r in ran if r["case"]["poses"] == n])
        for n in sorted({r["case"]["poses"] for r in ran})
    }

    return {
        "cases": len(results),
        "ran": len(ran),
        "skipped": sorted({r["skipped"] for r in results if "skipped" in r}),
        "detection": {
            "hidden": hidden,
            "named": sum(sum(r["detected"]) for r in ran),
            "rate": sum(sum(r["detected"]) for r in ran) / hidden if hidden else None,
            "per_effect": per_type,
            "per_size": per_size,
            "per_effect_and_size": dict(sorted(per_both.items())),
        },
        "false_alarms": {
            "clean_campaigns": len(clean),
            "with_any_effect": alarms,
            "rate": alarms / len(clean) if clean else None,
        },
        "doubt": doubt_rates(ran),
        "extra_effects_named": sum(len(r["extra"]) for r in ran if r["case"]["kind"] != "clean"),
        "holdout_over_floor": stats(ratios),
        "holdout_over_floor_outlier_cases": stats(outlier_ratios),
        "out_of_vocabulary": {
            "cases": len(oov),
            "named_something": sum(bool(r["named"]) for r in oov),
            "named_without_payoff": len(unpaid),
        },
        "seconds_per_case": stats(times),
        "seconds_per_case_by_size": by_size,
    }
