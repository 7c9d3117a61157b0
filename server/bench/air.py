"""The air temperature a thermal verification solves each compensated pose at, over a long run:
the indexed latest reading (store.latest_air) next to reading all of the campaign's readings
again before each pose (how it was found before), interleaved pose by pose in the same run."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

POSES = 1000
SEED = 3


def whole_campaign(db, cid: int) -> float | None:
    """The reference: the latest temperature found among all of the campaign's readings."""
    from robocal.server import store

    meas = store.campaign_measurements(db, campaign_id=cid)
    if meas.temp_c is None or meas.time_s is None:
        return None
    ok = np.isfinite(meas.temp_c) & np.isfinite(meas.time_s)
    if not ok.any():
        return None
    return float(meas.temp_c.flat[np.argmax(np.where(ok, meas.time_s, -np.inf))])


def run_air_bench(poses: int = POSES, url: str | None = None) -> dict:
    """Store a simulated run's readings pose by pose (in a SQLite file, or the database at
    `url`), asking before each pose for the latest temperature both ways; seconds per run."""
    from robocal.drivers.cell import VirtualCell
    from robocal.server import store

    from ..formats.cell_json import cell_to_json, default_cell

    cell = default_cell()
    meas = VirtualCell.random(cell.robot, cell.targets, seed=SEED).campaign(poses, seed=SEED)
    q_deg = np.rad2deg(meas.q)
    assert meas.time_s is not None and meas.temp_c is not None  # a simulated run has both
    last = (0.0, 0.0)
    spent = {"indexed_s": 0.0, "whole_campaign_s": 0.0, "store_readings_s": 0.0}
    with tempfile.TemporaryDirectory() as d:
        db = store.open_database(url or Path(d) / "air.db")
        try:
            cid = store.create_campaign(
                db, name="air", cell_json=cell_to_json(cell), poses_deg=q_deg, simulated=True
            )
            store.set_status(db, campaign_id=cid, status="running")
            for i in range(meas.n_poses):
                t0 = time.perf_counter()
                got = store.latest_air(db, campaign_id=cid)
                t1 = time.perf_counter()
                want = whole_campaign(db, cid)
                t2 = time.perf_counter()
                if (None if got is None else got.temp_c) != want:
                    raise AssertionError(f"pose {i}: {got} read, {want} in the readings")
                for k, t in enumerate(meas.target_names):
                    store.record_reading(db, campaign_id=cid, pose_index=i, target=t,
                                         xyz=meas.xyz[i, k], time_s=meas.time_s[i, k],
                                         temp_c=meas.temp_c[i, k])  # fmt: skip
                store.record_pose_outcome(
                    db, campaign_id=cid, pose_index=i, state="measured", reached_deg=q_deg[i]
                )
                last = (t1 - t0, t2 - t1)
                spent["indexed_s"] += t1 - t0
                spent["whole_campaign_s"] += t2 - t1
                spent["store_readings_s"] += time.perf_counter() - t2
        finally:
            db.close()
    return {
        "poses": poses,
        "targets": len(meas.target_names),
        "backend": "sqlite file" if url is None else db.engine.dialect.name,
        **{k: round(v, 4) for k, v in spent.items()},
        # the last pose's look-up, the campaign all but stored: constant against its length
        "last_pose_ms": {
            "indexed": round(1e3 * last[0], 3),
            "whole_campaign": round(1e3 * last[1], 3),
        },
        "speedup": round(spent["whole_campaign_s"] / spent["indexed_s"], 1),
        "reference": "whole_campaign_s: all of the campaign's readings read before each pose",
    }
