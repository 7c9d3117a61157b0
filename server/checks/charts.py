"""The chart of a model's quick checks over time (PNG, drawn in a worker process): each check's
RMS against the model's expected error and the level's watch and recalibrate limits, and the
change accumulated over the history against its own limits."""

from __future__ import annotations

import matplotlib.dates as mdates
import numpy as np
from matplotlib.figure import Figure

from robocal.server.figures.charts import _png
from robocal.server.store.model_checks import CheckRecord
from robocal.solver import drift

COLOURS = {"ok": "#5e81ac", "watch": "#d08770", "recalibrate": "#bf616a"}


def history_png(job_id: int, checks: list[CheckRecord], report=None) -> bytes:
    """RMS per check with the expected level and the limits; below, the accumulated change."""
    fig = Figure(figsize=(8, 5.5), layout="constrained")
    top, low = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    fig.suptitle(f"Job {job_id}'s model: quick checks ({len(checks)})")
    if not checks:
        top.text(0.5, 0.5, "never checked", ha="center", va="center", transform=top.transAxes)
        return _png(fig)
    when = [c.checked_at for c in checks]
    limits = np.array([drift.level_limits(c.expected_rms_mm, c.poses) for c in checks])
    steps = {"where": "mid"}
    top.step(when, [c.expected_rms_mm for c in checks], color="#4c566a", ls="--", **steps,
             label="expected (held-out)")  # fmt: skip
    top.step(when, limits[:, 0], color=COLOURS["watch"], ls=":", label="watch", **steps)
    top.step(when, limits[:, 1], color=COLOURS["recalibrate"], ls=":", label="recalibrate",
             **steps)  # fmt: skip
    top.plot(when, [c.rms_mm for c in checks], "-", color="#81a1c1", lw=1)
    low.plot(when, [c.cusum for c in checks], "-", color="#81a1c1", lw=1)
    for verdict, colour in COLOURS.items():
        at = [i for i, c in enumerate(checks) if c.verdict == verdict]
        if at:
            top.plot([when[i] for i in at], [checks[i].rms_mm for i in at], "o", color=colour,
                     label=f"check: {verdict}")  # fmt: skip
            low.plot([when[i] for i in at], [checks[i].cusum for i in at], "o", color=colour)
    low.axhline(drift.CUSUM_WATCH, color=COLOURS["watch"], ls=":")
    low.axhline(drift.CUSUM_H, color=COLOURS["recalibrate"], ls=":")
    top.set_ylabel("RMS error / mm")
    top.set_ylim(bottom=0)
    low.set_ylabel("accumulated change")
    low.set_ylim(bottom=0)
    low.xaxis.set_major_formatter(mdates.ConciseDateFormatter(low.xaxis.get_major_locator()))
    fig.legend(loc="outside lower center", fontsize=8, ncols=6)  # off the points
    for ax in (top, low):
        ax.grid(alpha=0.3)
    return _png(fig)


__all__ = ["history_png"]
