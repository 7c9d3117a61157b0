"""Acquisition benchmark: simulated campaign time and held-out accuracy of each procedure."""

from __future__ import annotations

import sys
import tempfile
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
}
TARGET_SPEEDUP, ACCURACY_TOL = 4.0, 0.10


def run_acquire_bench(seed: int = 0, holdout: int = 50) -> dict:
    """Each configuration on the same virtual cell; accuracy from minimax on held-out poses."""
    from robocal.drivers.cell import TrackerSpec, VirtualCell

    from . import workflow
    from .acquire import AcquireOptions, acquire
    from .formats.cell_json import default_cell

    cell = default_cell()
    truth = VirtualCell.random(
        cell.robot, cell.targets, seed=seed, tracker=TrackerSpec(**cell.tracker)
    )
    rng = np.random.default_rng([seed, 99])
    q_hold = truth.sample_poses(holdout, rng)
    meas_hold = truth.measure(q_hold, rng)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, opts in CONFIGS.items():
            print(f"[bench] acquire {label}", file=sys.stderr, flush=True)
            db = Path(tmp) / f"{label}.db"
            summary = acquire(db, cell, AcquireOptions(seed=seed, name=label, **opts))
            c, meas = workflow.load_data(db)
            cal = workflow.run_method(c, meas, "minimax")
            model = workflow.model_file(cal, c, meas)
            pred = workflow.model_predict(model, q_hold)[
                :, [list(model.targets).index(t) for t in truth.target_names]
            ]
            err = pred - meas_hold
            out[label] = {
                "options": opts,
                "campaign_s": summary["campaign_s"],
                "poses": summary["poses"],
                "readings": summary["readings"],
                "heldout_rmse_mm": float(np.sqrt(np.mean(np.sum(err**2, axis=-1)))),
                "locked_without_search_after_10": summary["locked_without_search_after_10"],
            }
    paper = out["paper"]
    for v in out.values():
        v["time_ratio_vs_paper"] = paper["campaign_s"] / v["campaign_s"]
        v["accuracy_ratio_vs_paper"] = v["heldout_rmse_mm"] / paper["heldout_rmse_mm"]
    best = out["combined"]
    return {
        "benchmark": "acquire",
        "seed": seed,
        "holdout_poses": holdout,
        "noise_floor_mm": truth.noise_floor_mm(q_hold),
        "configs": out,
        "target": {"speedup_min": TARGET_SPEEDUP, "accuracy_within": ACCURACY_TOL},
        "met": best["time_ratio_vs_paper"] >= TARGET_SPEEDUP
        and best["accuracy_ratio_vs_paper"] <= 1 + ACCURACY_TOL,
    }
