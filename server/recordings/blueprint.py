"""The layout a calibration's recording opens on: the cell, errors per pose, the solver."""

from __future__ import annotations

import numpy as np
import rerun.blueprint as rrb


def cell_eye(points: np.ndarray, base: np.ndarray) -> rrb.EyeControls3D:
    """A view of the whole cell from above and beside it, upright on the floor's normal.

    points (n, 3): what must be in sight (readings, tracker), tracker frame; base: 4x4.
    """
    pts = np.vstack([points, base[:3, 3]])
    target = (pts.min(axis=0) + pts.max(axis=0)) / 2
    span = float(np.max(pts.max(axis=0) - pts.min(axis=0))) or 1000.0
    up = base[:3, 2]
    side = base[:3, 0] - 0.8 * base[:3, 1]  # look from the front-left of the arm, down 30 deg
    side /= np.linalg.norm(side)
    position = target + 1.3 * span * (side + 0.6 * up)
    return rrb.EyeControls3D(position=position, look_target=target, eye_up=up)


def calibration_blueprint(
    *,
    eye: rrb.EyeControls3D,
    arm_eye: rrb.EyeControls3D,
    has_solver: bool,
    figures: tuple[tuple[str, str], ...] | list[tuple[str, str]] = (),
) -> rrb.Blueprint:
    """The cell with every pose left, one pose beside it, charts right; the time panel on the
    solver's timeline.

    eye: on the whole cell; arm_eye: on the arm at the pose its frames are drawn at.
    figures: (entity, title) of each diagnosis figure, one tab each.
    """
    cell = rrb.Spatial3DView(
        name="cell: every pose, errors coloured by size",
        origin="world",
        contents=["+ world/**", "- world/pose/**"],
        eye_controls=eye,
        line_grid=rrb.LineGrid3D(visible=False),  # the floor is drawn under the base instead
    )
    one_pose = rrb.Spatial3DView(
        name="one pose at a time (timeline: pose)",
        origin="world",
        contents=["+ world/pose/**", "+ world/tracker/**", "+ world/base/**", "+ world/floor/**"],
        eye_controls=eye,
        line_grid=rrb.LineGrid3D(visible=False),
    )
    frames = rrb.Spatial3DView(
        name="nominal and identified frames",
        origin="world",
        contents=["+ world/frames/**", "+ world/base/**", "+ world/floor/**"],
        eye_controls=arm_eye,
        line_grid=rrb.LineGrid3D(visible=False),
    )
    series: list[rrb.TimeSeriesView | rrb.Spatial2DView] = [
        rrb.TimeSeriesView(name="RMS error per pose / mm (timeline: pose)", origin="errors/rms")
    ]
    if has_solver:
        series.insert(
            0,
            rrb.TimeSeriesView(name="solver per iteration (timeline: iteration)", origin="solver"),
        )
    series += [rrb.Spatial2DView(name=title, origin=path) for path, title in figures]
    charts = rrb.Vertical(
        rrb.TextDocumentView(name="summary", origin="summary"),
        rrb.BarChartView(
            name="RMS error per pose / mm (bars: before, after)", origin="errors/per_pose"
        ),
        rrb.Tabs(*series),
        row_shares=[1, 2, 2],
    )
    return rrb.Blueprint(
        # one pose beside the whole cell, not in a tab behind it: choosing a pose (the page's
        # "Show this pose", or the time panel) shows its arm and arrows at once
        rrb.Horizontal(rrb.Tabs(cell, frames), one_pose, charts, column_shares=[3, 2, 2]),
        rrb.TimePanel(timeline="iteration" if has_solver else "pose", state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


__all__ = ["calibration_blueprint", "cell_eye"]
