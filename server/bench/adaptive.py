"""The adaptive campaign against fixed ones on the simulated cell, through the devices and store.

Per arm (the IRB 2600 and its three SMRs, a KUKA-like arm and a random 6R arm, each with a ring
of 1-4 SMRs) and seed: a fixed 80-pose campaign of random poses (RoboDK's default size), and per
target (a multiple of the tracker's noise floor) the adaptive campaign
(`acquire --target-accuracy-mm`) and a random campaign of as many poses as it measured. Each is
fitted with the adaptive campaign's fast fit (ls-sum, every reading) and measured on 50
independent poses of the same cell (tracker noise included, as a reading has it). Every
campaign orders its poses and settles adaptively, so the times compare the poses chosen.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ARMS = ("irb2600", "kuka-like", "random")
FACTORS = (2.0, 3.0)  # targets: these multiples of the tracker's noise floor
FIXED_POSES = 80
HOLDOUT = 50
# what the issue asks: the target reached in this share of runs, at most this share of the
# fixed campaign's poses and time on average, the prediction within this of the measured
HIT_SHARE, POSE_SHARE, TIME_SHARE, PREDICTION_TOL = 0.95, 0.5, 0.5, 0.2


def arm_cell(arm: str, seed: int):
    """The cell of an arm (the robot and its SMRs), drawn from seed."""
    from robocal.solver.robot import KUKA_LIKE

    from ..formats.cell_json import Cell, default_cell
    from . import diagnose_suite as ds

    irb = default_cell()
    if arm == "irb2600":
        return irb
    rng = np.random.default_rng([0xADA, seed])
    robot = KUKA_LIKE if arm == "kuka-like" else ds.random_arm(rng, f"random-6r-{seed}")
    return Cell(robot, ds.smr_ring(rng))


def _heldout(db, cell, campaign: int, q_hold, meas_hold, exts=()) -> float:
    """Held-out 3-D RMS (mm) on the independent poses of the campaign's ls-sum fit, with the
    effects exts (the adaptive campaign's named ones) fitted beside the geometry."""
    from robocal.server import store
    from robocal.server.acquisition.adaptive_effects import fit_campaign

    meas = store.campaign_measurements(db, campaign_id=campaign, targets=sorted(cell.targets))
    err = fit_campaign(cell, meas, exts).predict(q_hold) - meas_hold
    return float(np.sqrt(np.nanmean(np.sum(err**2, axis=-1))))


def run_arm(arm: str, seed: int, factors=FACTORS, effects=()) -> dict:
    """One arm and seed: the fixed campaign, and per target the adaptive and the random one;
    effects: hidden physics of the simulated arm (`simulate --effect` specs), which no fit of
    the geometry captures."""
    from robocal.drivers.cell import TrackerSpec, VirtualCell
    from robocal.drivers.effects import make_effects
    from robocal.server.acquisition.acquire import AcquireOptions, acquire
    from robocal.server.acquisition.adaptive_effects import from_steps

    from .. import store

    cell = arm_cell(arm, seed)
    names = sorted(cell.targets)
    truth = VirtualCell.random(
        cell.robot,
        {n: cell.targets[n] for n in names},
        seed=seed,
        tracker=TrackerSpec.of(cell.tracker),
    )
    # the arm the simulated devices move (drivers/simulated_cell.py builds it so)
    truth.effects.extend(make_effects(list(effects), truth, seed))
    rng = np.random.default_rng([seed, 0x401D])
    q_hold = truth.sample_poses(HOLDOUT, rng)
    meas_hold = truth.measure(q_hold, rng)
    floor = truth.noise_floor_mm(q_hold)
    common: dict[str, Any] = dict(seed=seed, order=True, settle="adaptive", effects=tuple(effects))
    out: dict = {"arm": arm, "seed": seed, "smrs": len(names), "floor_mm": floor, "targets": {}}
    out["effects"] = list(effects)
    with tempfile.TemporaryDirectory() as tmp, store.open_database(Path(tmp) / "b.db") as db:

        def run(name: str, exts=(), **kw) -> dict:
            s = acquire(db, cell, AcquireOptions(name=name, **common, **kw))
            a = s.adaptive
            if a is not None and a.steps:  # the model the adaptive campaign ends with
                exts = from_steps(a.steps[-1].extensions)
            return {
                "poses": s.poses,
                "campaign_s": s.campaign_s,
                "heldout_mm": _heldout(db, cell, s.campaign, q_hold, meas_hold, exts),
                "adaptive": a,
                "extensions": exts,
            }

        fixed = run("fixed", poses=FIXED_POSES)
        out["fixed"] = {k: fixed[k] for k in ("poses", "campaign_s", "heldout_mm")}
        for f in factors:
            target = f * floor
            a = run(f"adaptive-x{f:g}", poses=FIXED_POSES, target_accuracy_mm=target)
            # as many random poses, fitted with the same effects
            r = run(f"random-x{f:g}", a["extensions"], poses=a["poses"])
            adaptive = a["adaptive"]
            steps, predicted = adaptive.steps, adaptive.predicted_mm
            out["targets"][f"{f:g}"] = {
                "target_mm": target,
                "poses": a["poses"],
                "campaign_s": a["campaign_s"],
                "heldout_mm": a["heldout_mm"],
                "predicted_mm": predicted,
                "stopped": adaptive.stopped,
                "reached": a["heldout_mm"] <= target,
                "prediction_error": predicted / a["heldout_mm"] - 1.0,
                "random_heldout_mm": r["heldout_mm"],
                "random_campaign_s": r["campaign_s"],
                "steps": [(s.poses, round(s.predicted_mm, 5)) for s in steps],
                "last_step": steps[-1].to_json(),
                "effects": list(steps[-1].effects),
                # every effect a checkpoint's diagnosis named (on a clean cell: false alarms)
                "named": sorted({n for s in steps for n in (s.named or ())}),
                "diagnoses": sum(s.named is not None for s in steps),
            }
            print(
                f"[bench] {arm} seed {seed} x{f:g}: {a['poses']} poses, {a['campaign_s'] / 60:.1f} "
                f"min, held-out {a['heldout_mm']:.4f} mm (target {target:.4f}, predicted "
                f"{predicted:.4f}; random {r['heldout_mm']:.4f}; fixed 80: "
                f"{fixed['heldout_mm']:.4f} in {fixed['campaign_s'] / 60:.1f} min)",
                file=sys.stderr,
                flush=True,
            )
    return out


def summarize(runs: list[dict], factors=FACTORS) -> dict:
    """Per target over every run: the share reaching it, poses and time against the fixed
    campaign's, held-out against random at equal poses, and the prediction's error."""
    out: dict[str, dict[str, Any]] = {}
    for f in factors:
        key = f"{f:g}"
        t = [r["targets"][key] for r in runs]
        fixed_poses = np.mean([r["fixed"]["poses"] for r in runs])
        fixed_s = np.mean([r["fixed"]["campaign_s"] for r in runs])
        err = np.array([abs(x["prediction_error"]) for x in t])
        ratio = np.array([x["heldout_mm"] / x["random_heldout_mm"] for x in t])
        out[key] = {
            "runs": len(t),
            "reached_share": float(np.mean([x["reached"] for x in t])),
            "missed": [
                {
                    "arm": r["arm"],
                    "seed": r["seed"],
                    **{k: x[k] for k in ("heldout_mm", "target_mm", "stopped")},
                }
                for r, x in zip(runs, t)
                if not x["reached"]
            ],
            "stopped": {
                s: sum(x["stopped"] == s for x in t) for s in ("target", "floor", "maximum")
            },
            "poses_mean": float(np.mean([x["poses"] for x in t])),
            "pose_share_of_fixed": float(np.mean([x["poses"] for x in t]) / fixed_poses),
            "minutes_mean": float(np.mean([x["campaign_s"] for x in t]) / 60.0),
            "time_share_of_fixed": float(np.mean([x["campaign_s"] for x in t]) / fixed_s),
            "heldout_mean_mm": float(np.mean([x["heldout_mm"] for x in t])),
            "random_heldout_mean_mm": float(np.mean([x["random_heldout_mm"] for x in t])),
            "heldout_over_random_mean": float(ratio.mean()),
            "no_worse_than_random_share": float(np.mean(ratio <= 1.0)),
            "prediction_error_mean": float(err.mean()),
            "prediction_within_share": float(np.mean(err <= PREDICTION_TOL)),
            # checkpoints' diagnoses: runs that ran one, that named an effect, that fitted one
            "diagnosed_runs": int(sum(x.get("diagnoses", 0) > 0 for x in t)),
            "named_runs": int(sum(bool(x.get("named")) for x in t)),
            "effects_runs": int(sum(bool(x.get("effects")) for x in t)),
        }
        v = out[key]
        v["met"] = bool(
            v["reached_share"] >= HIT_SHARE
            and v["pose_share_of_fixed"] <= POSE_SHARE
            and v["time_share_of_fixed"] <= TIME_SHARE
            and v["heldout_over_random_mean"] <= 1.0
            and v["prediction_within_share"] >= HIT_SHARE
        )
    return out


def run_adaptive_suite(
    seeds: int = 20, arms=ARMS, factors=FACTORS, effects=(), first_seed: int = 0
) -> dict:
    """Every arm x seed (first_seed on); the runs and their summary per target."""
    chosen = range(first_seed, first_seed + seeds)
    runs = [run_arm(arm, s, factors, effects) for s in chosen for arm in arms]
    return {
        "effects": list(effects),
        "arms": list(arms),
        "seeds": seeds,
        "first_seed": first_seed,
        "fixed_poses": FIXED_POSES,
        "holdout_poses": HOLDOUT,
        "fit": "ls-sum",
        "summary": summarize(runs, factors),
        "fixed": {
            "poses": FIXED_POSES,
            "minutes_mean": float(np.mean([r["fixed"]["campaign_s"] for r in runs]) / 60.0),
            "heldout_mean_mm": float(np.mean([r["fixed"]["heldout_mm"] for r in runs])),
        },
        "runs": runs,
    }
