"""Diagnosis benchmark: wall time of `diagnose` and of each stage, on simulated campaigns."""

from __future__ import annotations

import sys
import time

import numpy as np

# (label, effect specs): a clean campaign, one hidden effect, two at once
CASES = (("clean", ()), ("joint_periodic", ("joint_periodic:3:2=0.01",)),
         ("joint_compliance", ("joint_compliance:2=0.3",)),
         ("two_effects", ("joint_periodic:4:2=0.015", "thermal_drift=25")))
TARGET_S = 30.0


def run_diagnose_bench(poses: int = 100, seed: int = 0) -> dict:
    """Time diagnose on each case; the stages come from the report's own clock."""
    from drivers.cell import VirtualCell
    from drivers.effects import make_effects
    from solver.diagnose import diagnose

    from .formats.cell_json import default_cell

    cell = default_cell()
    names = tuple(cell.targets)
    targets = np.array([cell.targets[t] for t in names])
    out = {}
    for label, specs in CASES:
        vc = VirtualCell.random(cell.robot, cell.targets, seed=seed)
        vc.effects.extend(make_effects(specs, vc, seed))
        meas = vc.campaign(poses, seed=seed)
        print(f"[bench] diagnose {label}: {poses} poses", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        d = diagnose(cell.robot, targets, meas.target_names, meas.q, meas.xyz, meas.time_s,
                     meas.temp_c)
        wall = time.perf_counter() - t0
        out[label] = {"effects_simulated": list(specs), "seconds": wall,
                      "stages_seconds": d.report["seconds"],
                      "fits": d.report["cross_validation"]["fits"],
                      "effects_found": [e["name"] + (f":{e['joint']}" if "joint" in e else "")
                                        for e in d.report["effects"]],
                      "final_holdout_rmse_mm": d.report["final"]["holdout_rmse_mm"],
                      "noise_floor_mm": vc.noise_floor_mm(meas.q)}
    worst = max(v["seconds"] for v in out.values())
    return {"benchmark": "diagnose", "poses": poses, "readings_per_pose": len(names),
            "cases": out, "target_seconds_max": TARGET_S, "worst_seconds": worst,
            "met": worst <= TARGET_S}
