"""The validation guard's false alarms and catches, as JSON: clean simulated campaigns (30 to
200 poses) must be deployable; those with a hidden effect the model lacks are flagged where it
leaves more than 3x the noise floor held out (no tolerance given); small ones (5 and 8 poses)
must be flagged; the real campaigns' verdicts with their reasons.

    python -m robocal.server.bench.validation [--seeds 20] [--method minimax] [--real DIR...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

POSES = (30, 50, 100, 150, 200)
EFFECTS = (
    "joint_compliance:2",
    "joint_periodic:3:1",
    "thermal_drift",
    "joint_scale:2",
    "base_shift",
    "joint_backlash:3",
    "joint_coupling:5",
)
SMALL = (5, 8)  # campaigns the guard must flag


def simulated(seed: int, poses: int, effects: list[str], method: str) -> dict:
    """The verdict on one simulated campaign of the default cell."""
    from robocal.drivers.cell import TrackerSpec, VirtualCell
    from robocal.drivers.effects import make_effects
    from robocal.server.calibration import workflow

    cell = workflow.load_cell(None)
    vc = VirtualCell.random(
        cell.robot, cell.targets, seed=seed, tracker=TrackerSpec.of(cell.tracker)
    )
    vc.effects.extend(make_effects(effects, vc, seed))
    meas = vc.campaign(poses, seed=seed)
    return _verdict(cell, meas, method) | {"seed": seed, "poses": poses, "effects": effects}


def real(folder: Path, method: str) -> dict:
    """The verdict on a real campaign: its train.csv with its cell.json."""
    from robocal.server.calibration import workflow

    cell, meas = workflow.load_data(folder / "train.csv", folder / "cell.json")
    return _verdict(cell, meas, method) | {"campaign": folder.name, "poses": meas.n_poses}


def _verdict(cell, meas, method) -> dict:
    from robocal.server.calibration import workflow
    from robocal.solver.identifiability import NotIdentifiable

    t0 = time.perf_counter()
    try:
        if method == "diagnose":  # the diagnosis's final model, its extensions included
            v = workflow.diagnose(cell, meas, screen=False)[1].verdict
        else:
            cal = workflow.run_method(cell, meas, method)
            v = workflow.model_file(cal, cell, meas).verdict
    except NotIdentifiable as e:  # refused before any model: as good as flagged
        return {"deployable": False, "reasons": [f"refused: {e}"], "refused": True}
    return {
        "deployable": v.deployable,
        "reasons": list(v.reasons),
        "holdout_rms_mm": v.holdout_rms_mm,
        "holdout_max_mm": v.holdout_max_mm,
        "fit_rms_mm": v.fit_rms_mm,
        "condition_number": v.condition_number,
        "noise_floor_mm": v.noise_floor_mm,
        "seconds": round(time.perf_counter() - t0, 3),
    }


def run(seeds: int, method: str, real_dirs: list[Path]) -> dict:
    healthy = []
    for seed in range(seeds):
        effects = [] if seed % 2 == 0 else [EFFECTS[(seed // 2) % len(EFFECTS)]]
        healthy.append(simulated(seed, POSES[seed % len(POSES)], effects, method))
    small = [simulated(seed, n, [], method) for n in SMALL for seed in range(5)]
    reals = [real(d, method) for d in real_dirs]
    clean = [c for c in healthy if not c["effects"]]
    effect = [c for c in healthy if c["effects"]]
    return {
        "method": method,
        "clean": {
            "campaigns": len(clean),
            "flagged": sum(not c["deployable"] for c in clean),  # false alarms
            "cases": clean,
        },
        "effect": {
            "campaigns": len(effect),
            "flagged": sum(not c["deployable"] for c in effect),  # an effect the model lacks
            "cases": effect,
        },
        "small": {
            "campaigns": len(small),
            "flagged": sum(not c["deployable"] for c in small),
            "cases": small,
        },
        "real": {
            "campaigns": len(reals),
            "flagged": sum(not c["deployable"] for c in reals),
            "cases": reals,
        },
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m robocal.server.bench.validation")
    p.add_argument(
        "--seeds",
        type=int,
        default=20,
        help="simulated campaigns, every other one with a hidden effect",
    )
    p.add_argument(
        "--method", default="minimax", help="calibration method, or diagnose (its final model)"
    )
    p.add_argument("--real", nargs="*", default=[], help="folders with train.csv and cell.json")
    args = p.parse_args(argv)
    json.dump(run(args.seeds, args.method, [Path(d) for d in args.real]), sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
