"""A campaign writer for the crash test: resumes where the store says, prints each commit.

Run as `python -m tests.server.store.crash_writer DB CAMPAIGN_ID DELAY_S`. It does what a campaign
engine does at each pose, with a fake tracker whose readings depend only on (pose, target), so
the test can check every stored value.
"""

from __future__ import annotations

import sys
import time

from robocal.server.store import (
    next_unmeasured_pose,
    open_database,
    planned_poses,
    pose_readings,
    record_missing,
    record_pose_outcome,
    record_reading,
    set_status,
)

TARGETS = ("A", "B", "C")


def beam_broken(pose: int, target: str) -> bool:
    """The fake tracker loses target C at every seventh pose."""
    return target == "C" and pose % 7 == 3


def fake_reading(pose: int, target: str) -> dict:
    """The fake tracker's reading of a target at a pose."""
    k = TARGETS.index(target)
    return dict(
        xyz=(1000.0 + pose + 0.125 * k, -500.0 + 0.001 * pose, 250.0 + k / 3),
        std=(0.001, 0.002, 0.003),
        samples=20,
        time_s=2.0 * pose + 0.5 * k,
        temp_c=20.0 + 0.001 * pose,
    )


def main(path: str, campaign_id: int, delay_s: float) -> None:
    db = open_database(path)
    set_status(db, campaign_id=campaign_id, status="running")  # a no-op after a kill
    plan = planned_poses(db, campaign_id=campaign_id)
    while (i := next_unmeasured_pose(db, campaign_id=campaign_id)) is not None:
        stored = pose_readings(db, campaign_id=campaign_id, pose_index=i)
        for t in TARGETS:
            if t in stored:  # committed before the kill: keep it, do not measure it again
                print("kept", i, t, flush=True)
                continue
            if beam_broken(i, t):
                record_missing(
                    db,
                    campaign_id=campaign_id,
                    pose_index=i,
                    target=t,
                    detail="beam break after 2 retries",
                )
            else:
                record_reading(
                    db, campaign_id=campaign_id, pose_index=i, target=t, **fake_reading(i, t)
                )
            print("reading", i, t, flush=True)  # only once the commit has returned
            time.sleep(delay_s)
        state = "missing-target" if any(beam_broken(i, t) for t in TARGETS) else "measured"
        record_pose_outcome(
            db, campaign_id=campaign_id, pose_index=i, state=state, reached_deg=plan[i].joints_deg
        )
        print("pose", i, flush=True)
    set_status(db, campaign_id=campaign_id, status="done")
    print("done", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]))
