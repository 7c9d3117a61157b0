"""Recording benchmark: size and write time of a calibration's .rrd beside the calibration's time.

Run: `uv run python -m robocal.server.bench.recording` (JSON on stdout).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SIZES = ((100, 50), (1000, 200))  # (calibration poses, held-out poses)
REPEATS = 3  # the best of these: other load on the machine only adds time


def _best(fn, *args, **kwargs):
    """The fastest of REPEATS calls (after one untimed call that warms caches) and its result."""
    result = fn(*args, **kwargs)
    best = float("inf")
    for _ in range(REPEATS):
        t = time.perf_counter()
        result = fn(*args, **kwargs)
        best = min(best, time.perf_counter() - t)
    return best, result


def run_recording_bench(sizes=SIZES, seed: int = 1) -> dict:
    """Per campaign size: minimax's time, the nominal registration's, the recording's and its size."""
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    from robocal.drivers.cell import VirtualCell
    from robocal.server.calibration.workflow import run_method
    from robocal.server.recordings.calibration import record_calibration

    from ..formats.cell_json import default_cell

    cell = default_cell()
    targets = {k: list(v) for k, v in cell.targets.items()}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n, h in sizes:
            meas = VirtualCell.random(cell.robot, targets, seed=seed).campaign(n + h, seed=seed)
            fit, held = meas.subset(np.arange(n)), meas.subset(np.arange(n, n + h))
            t_cal, cal = _best(run_method, cell, fit, "minimax")
            t_nom, nominal = _best(run_method, cell, fit, "nominal")
            t_rec, path = _best(
                record_calibration,
                Path(tmp) / f"{n}.rrd",
                cell=cell,
                meas=fit,
                calibration=cal,
                nominal=nominal,
                held_out=held,
            )
            rows.append(
                {
                    "poses": n,
                    "held_out_poses": h,
                    "readings": fit.n_readings + held.n_readings,
                    "calibration_minimax_s": round(t_cal, 4),
                    "nominal_registration_s": round(t_nom, 4),
                    "recording_s": round(t_rec, 4),
                    "recording_over_calibration": round(t_rec / t_cal, 2),
                    "rrd_bytes": path.stat().st_size,
                }
            )
    return {"bench": "recording", "seed": seed, "runs": rows}


if __name__ == "__main__":
    json.dump(run_recording_bench(), sys.stdout, indent=2)
    sys.stdout.write("\n")
