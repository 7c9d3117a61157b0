"""Verification benchmark: an ISO 9283 run on the simulated cell after its calibration, its
simulated duration and figures next to the calibration campaign's, measured in the same run."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

SEED = 6
EFFECT = "joint_compliance:2=1.0"


def run_verify_bench(seed: int = SEED, cycles: int = 3, directions: int = 3) -> dict:
    """Calibrate a simulated cell (100 poses, diagnosed), then verify its model on the cube."""
    from robocal.server import store
    from robocal.server.acquisition.acquire import AcquireOptions, acquire
    from robocal.server.calibration import workflow
    from robocal.server.verify.certificate import holdout_rms
    from robocal.server.verify.run import VerifyOptions, verify

    from ..formats.cell_json import default_cell
    from ..formats.model_json import write_model

    cell = default_cell()
    with tempfile.TemporaryDirectory() as d:
        db_path, model_path = Path(d) / "bench.db", Path(d) / "model.json"
        t0 = time.perf_counter()
        acquired = acquire(db_path, cell, AcquireOptions(poses=100, seed=seed, effects=(EFFECT,)))
        cal_wall = time.perf_counter() - t0
        meas = store.campaign_measurements(
            store.open_database(db_path),
            campaign_id=acquired.campaign,
            targets=tuple(sorted(cell.targets)),
        )
        _, model = workflow.diagnose(cell, meas, screen=False)
        write_model(model_path, model)
        t0 = time.perf_counter()
        opts = VerifyOptions(cycles=cycles, directions=directions, seed=seed, effects=(EFFECT,))
        report = verify(db_path, cell, model_path, opts)
        wall = time.perf_counter() - t0
    visits = 2 * 5 * cycles * directions  # each visit has its approach pose
    return {
        "seed": seed,
        "effect": EFFECT,
        "cycles": cycles,
        "directions": directions,
        "poses_per_run": visits,
        "holdout_rms_mm": holdout_rms(report.model),
        "AP_before_mm": report.before.AP_max_mm,
        "AP_after_mm": report.after.AP_max_mm,
        "RP_before_mm": report.before.RP_max_mm,
        "RP_after_mm": report.after.RP_max_mm,
        "simulated_s": report.simulated_s,
        "wall_s": wall,
        "reference": {
            "calibration_poses": 100,
            "simulated_s": acquired.campaign_s,
            "wall_s": cal_wall,
        },
    }
