"""A campaign's readings as a rerun recording, in pieces as poses finish: what the page's 3-D
viewer shows live while the campaign acquires.

Stateless: each piece is a whole .rrd of the poses from `first` on that have an outcome, all
under one recording id per campaign, so the viewer adds each piece to the same recording.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

# Never phone home (the workstation may be offline); the bytes go to the page only.
os.environ.setdefault("RERUN_ANALYTICS", "0")

import rerun as rr  # noqa: E402
import rerun.blueprint as rrb  # noqa: E402

from robocal.server import store  # noqa: E402

# one colour per target (SMR), cycled: saturated, so the readings stand out on the dark viewer
TARGET_COLORS = ((0, 200, 255), (255, 0, 200), (120, 255, 0), (255, 230, 0))
LATEST = (30, 90, 255)  # the last pose done, drawn over its readings
RADIUS_MM = 25.0
AXES_MM = 300.0


@dataclass(frozen=True)
class LivePiece:
    """A piece of a campaign's live recording: its bytes (empty: nothing new) and the first pose
    the next piece starts at."""

    rrd: bytes
    next_pose: int
    poses: int  # poses in this piece


def recording_id(campaign_id: int) -> str:
    return f"robocal-campaign-{campaign_id}"


def live_blueprint(campaign_id: int) -> rrb.Blueprint:
    """The readings so far in 3-D beside the poses' log; the time panel follows the last pose."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name=f"campaign {campaign_id}: readings so far", origin="world"),
            rrb.TextLogView(name="poses", origin="poses"),
            column_shares=[3, 1],
        ),
        rrb.TimePanel(timeline="pose", state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


def campaign_piece(db: store.Database, campaign_id: int, first: int) -> LivePiece:
    """The poses from `first` on that have an outcome, up to the first one without (a pose in
    progress comes in the next piece, whole); from 0 also the tracker and the layout."""
    plan = store.planned_poses(db, campaign_id=campaign_id)
    stop = first
    for p in plan[first:]:  # contiguous: a resumed run fills the plan in order
        if p.state is None:
            break
        stop = p.index + 1
    done = plan[first:stop]
    if first > 0 and not done:
        return LivePiece(b"", first, 0)
    readings = store.readings_of_poses(db, campaign_id=campaign_id, first=first, stop=stop)
    rec = rr.RecordingStream(
        "robocal", recording_id=recording_id(campaign_id), send_properties=False
    )
    stream = rr.binary_stream(recording=rec)
    if first == 0:
        rec.send_blueprint(live_blueprint(campaign_id))
        rec.log(
            "world/tracker",
            rr.TransformAxes3D(axis_length=AXES_MM),
            rr.Points3D([[0.0, 0.0, 0.0]], radii=40.0, labels=["laser tracker"]),
            static=True,
        )
    by_pose: dict[int, list] = {}
    for r in readings:
        if r.xyz is not None:
            by_pose.setdefault(r.pose_index, []).append(r)
    for p in done:
        rec.set_time("pose", sequence=p.index)
        got = by_pose.get(p.index, [])
        xyz = np.array([r.xyz for r in got], dtype=float).reshape(-1, 3)
        # by the target's name, so a target keeps its colour from one piece to the next
        colors = [TARGET_COLORS[sum(r.target.encode()) % len(TARGET_COLORS)] for r in got]
        # every reading stays drawn (static, one entity per pose); the latest pose over them
        rec.log(
            f"world/readings/pose_{p.index:05d}",
            rr.Points3D(xyz, colors=colors, radii=RADIUS_MM),
            static=True,
        )
        rec.log("world/latest", rr.Points3D(xyz, colors=[LATEST], radii=1.6 * RADIUS_MM))
        words = f"pose {p.index} ({p.label}): {p.state}, {len(got)} reading(s)"
        rec.log("poses", rr.TextLog(words + (f"; {p.detail}" if p.detail else "")))
    data = stream.read() or b""
    return LivePiece(data, stop, len(done))


__all__ = ["LivePiece", "campaign_piece", "live_blueprint", "recording_id"]
