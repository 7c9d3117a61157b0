"""Acquisition benchmark: simulated campaign time, its physical bound, and held-out accuracy of
each procedure."""

from __future__ import annotations

import sys
import tempfile
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

# label -> acquire options: the paper's procedure first, then each saving, then all of them
# AcquireOptions keywords per configuration
CONFIGS: dict[str, dict[str, Any]] = {
    "paper": dict(poses=100, settle="fixed"),
    "adaptive_settling": dict(poses=100, settle="adaptive"),
    "ordered": dict(poses=100, settle="fixed", order=True),
    "observability_40_of_400": dict(poses=40, settle="fixed", choose_from=400),
    "combined": dict(poses=40, settle="adaptive", order=True, choose_from=400),
    # RoboDK's default size, ordered and settled as the adaptive campaigns are: their reference
    "fixed_80": dict(poses=80, settle="adaptive", order=True),
    # `acquire --target-accuracy-mm`, the target this multiple of the tracker's noise floor
    "adaptive_x2": dict(poses=80, settle="adaptive", order=True, target_floor_factor=2.0),
    "adaptive_x3": dict(poses=80, settle="adaptive", order=True, target_floor_factor=3.0),
}
TARGET_SPEEDUP, ACCURACY_TOL, BOUND_RATIO_MAX = 4.0, 0.10, 1.2


BOUND_METHOD = (
    "motion: the Held-Karp (1-tree) bound on a path from the start through every measured "
    "pose over the controller's move times (any visiting order is such a path; the bound is at "
    "least the minimum spanning tree's, shown as motion_spanning_tree_s); measuring: "
    "readings x samples / rate; settling: per measured pose, the earliest start after arrival "
    "at which the simulated ringing's spread over a reading's window, in the direction most "
    "favourable to it, passes the tracker's inaccurate-spread check (noise ignored, which only "
    "adds spread); aiming: one beam reads a pose's SMRs one after another, all after the "
    "settling, so between consecutive readings the head moves and locks (the simulated "
    "tracker's POINT, fixed seconds): (readings - measured poses) x POINT (the first SMR's "
    "point may happen during the move). tour_s, the best order found, is shown beside: not a "
    "bound"
)


def _spanning_tree_s(q_rad, start) -> float:
    """The earlier, looser motion bound: a minimum spanning tree of the move times."""
    from robocal.drivers.campaign_bound import spanning_tree_weight
    from robocal.drivers.planning import move_time

    nodes = np.vstack([np.asarray(start, dtype=float)[None], np.asarray(q_rad, dtype=float)])
    return spanning_tree_weight(move_time(nodes[:, None], nodes[None]))


def physical_bound(
    q_rad, readings: int, samples: int, sample_rate_hz: float, start, sigma_mm
) -> dict:
    """The least time any procedure needs for these poses and readings: the motion's lower bound
    (a minimum spanning tree of the move times), the samples themselves, per pose the wait
    before the arm's ringing lets a reading pass the tracker's check (sigma_mm: per pose, the
    noise of its farthest SMR), and the beam's re-aiming between a pose's readings. The best
    order found (`tour_s`) is shown beside, not a bound."""
    from robocal.drivers.campaign_bound import (
        aiming_lower_bound,
        motion_lower_bound,
        settling_lower_bound,
    )
    from robocal.drivers.planning import order_poses, total_move_time

    motion = motion_lower_bound(q_rad, start)
    measuring = readings * samples / sample_rate_hz
    settle = settling_lower_bound(sigma_mm, samples, sample_rate_hz)
    settling = float(settle.earliest_s.sum())
    aiming = aiming_lower_bound(readings, len(q_rad))
    return {
        "bound_s": motion + measuring + settling + aiming,
        "motion_s": motion,
        "motion_spanning_tree_s": _spanning_tree_s(q_rad, start),
        "measuring_s": measuring,
        "settling_s": settling,
        "aiming_s": aiming,
        # the bound without the aiming term, as the earlier benchmarks stated it
        "bound_without_aiming_s": motion + measuring + settling,
        "settling_per_pose_s": [float(settle.earliest_s.min()), float(settle.earliest_s.max())],
        "ring_shift_of_mean_mm_max": float(settle.mean_shift_mm.max()),
        "tour_s": total_move_time(q_rad, order_poses(q_rad, start), start),
    }


def run_acquire_bench(
    seed: int = 0,
    holdout: int = 50,
    configs=None,
    suite_seeds: int = 0,
    suite_effects=(),
    first_seed: int = 0,
) -> dict:
    """Each configuration on the same virtual cell; accuracy from minimax on held-out poses.
    suite_seeds > 0 adds the adaptive campaign's suite (bench/adaptive.py) over that many seeds
    of each arm from first_seed, its arms with the hidden effects suite_effects."""
    from robocal.drivers.cell import TrackerSpec, VirtualCell
    from robocal.drivers.tracker.sim import SAMPLE_RATE_HZ
    from robocal.server.acquisition.acquire import AcquireOptions, acquire
    from robocal.server.calibration import workflow

    from ..formats.cell_json import default_cell

    configs = CONFIGS if configs is None else configs
    cell = default_cell()
    truth = VirtualCell.random(
        cell.robot, cell.targets, seed=seed, tracker=TrackerSpec.of(cell.tracker)
    )
    rng = np.random.default_rng([seed, 99])
    q_hold = truth.sample_poses(holdout, rng)
    meas_hold = truth.measure(q_hold, rng)
    home = np.zeros(cell.robot.n_joints)  # where acquire starts the arm and plans from
    floor = truth.noise_floor_mm(q_hold)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, kw in configs.items():
            print(f"[bench] acquire {label}", file=sys.stderr, flush=True)
            db = Path(tmp) / f"{label}.db"
            factor = kw.get("target_floor_factor")
            run_kw = {k: v for k, v in kw.items() if k != "target_floor_factor"}
            if factor is not None:
                run_kw["target_accuracy_mm"] = factor * floor
            opts = AcquireOptions(seed=seed, name=label, **run_kw)
            summary = acquire(db, cell, opts)
            campaign_s = summary.campaign_s
            assert campaign_s is not None  # a new campaign: its time measured
            c, meas = workflow.load_data(db)
            seen = np.isfinite(meas.xyz).all(axis=-1)
            measured = seen.any(axis=1)  # poses with a reading: the ones the arm settled at
            bound = physical_bound(
                meas.q[measured],
                summary.readings,
                opts.samples,
                SAMPLE_RATE_HZ,
                home,
                truth.tracker.sigma_mm(
                    np.linalg.norm(truth.true_points(meas.q[measured]), axis=-1)
                ).max(axis=1),
            )
            cal = workflow.run_method(c, meas, "minimax")
            model = workflow.model_file(cal, c, meas)
            pred = workflow.model_predict(model, q_hold)[
                :, [list(model.targets).index(t) for t in truth.target_names]
            ]
            err = pred - meas_hold
            out[label] = {
                "options": kw,
                "campaign_s": campaign_s,
                "bound": bound,
                "ratio_to_bound": campaign_s / bound["bound_s"],
                "poses": summary.poses,
                "poses_in_bound": int(measured.sum()),
                "readings": summary.readings,
                "searched": summary.searched,
                "heldout_rmse_mm": float(np.sqrt(np.mean(np.sum(err**2, axis=-1)))),
                "campaign_min": campaign_s / 60.0,
                "locked_without_search_after_10": summary.locked_without_search_after_10,
                # where the campaign's time went, beside the bound's terms
                "phase_s": asdict(summary.phase_s),
                "over_bound_s": {
                    "motion": summary.phase_s.move - bound["motion_s"],
                    "of_which_tour_over_motion_bound": bound["tour_s"] - bound["motion_s"],
                    "measure_beyond_sampling": summary.phase_s.measure - bound["measuring_s"],
                    "aim": summary.phase_s.aim - bound["aiming_s"],
                    "settle": summary.phase_s.settle,
                    "other": summary.phase_s.other,
                },
            }
            if summary.adaptive is not None:
                a = summary.adaptive
                out[label]["adaptive"] = {
                    "target_mm": opts.target_accuracy_mm,
                    "stopped": a.stopped,
                    "predicted_mm": a.predicted_mm,
                    "steps": [(s.poses, s.predicted_mm) for s in a.steps],
                }
            print(
                f"[bench] {label}: {summary.campaign_s:.1f} s, bound "
                f"{bound['bound_s']:.1f} s (motion {bound['motion_s']:.1f} + measuring "
                f"{bound['measuring_s']:.1f} + settling {bound['settling_s']:.2f} + aiming "
                f"{bound['aiming_s']:.1f}; tour "
                f"{bound['tour_s']:.1f}), ratio {out[label]['ratio_to_bound']:.3f}",
                file=sys.stderr,
                flush=True,
            )
    paper = out.get("paper")
    for v in out.values():
        if paper is not None:
            v["time_ratio_vs_paper"] = paper["campaign_s"] / v["campaign_s"]
            v["accuracy_ratio_vs_paper"] = v["heldout_rmse_mm"] / paper["heldout_rmse_mm"]
    # the speed target is the fixed procedures' (an adaptive one is judged by its target)
    fixed = [k for k in out if "adaptive" not in out[k]]
    fastest = min(fixed, key=lambda k: out[k]["campaign_s"])
    best = out[fastest]
    suite = None
    if suite_seeds:
        from .adaptive import run_adaptive_suite

        suite = run_adaptive_suite(
            seeds=suite_seeds, effects=tuple(suite_effects), first_seed=first_seed
        )
    return {
        "benchmark": "acquire",
        "adaptive_suite": suite,
        "seed": seed,
        "holdout_poses": holdout,
        "noise_floor_mm": floor,
        "bound_method": BOUND_METHOD,
        "configs": out,
        "fastest": fastest,
        "target": {
            "speedup_min": TARGET_SPEEDUP,
            "accuracy_within": ACCURACY_TOL,
            "ratio_to_bound_max": BOUND_RATIO_MAX,
        },
        "met": paper is not None
        and best["time_ratio_vs_paper"] >= TARGET_SPEEDUP
        and best["accuracy_ratio_vs_paper"] <= 1 + ACCURACY_TOL
        and best["ratio_to_bound"] <= BOUND_RATIO_MAX,
    }
