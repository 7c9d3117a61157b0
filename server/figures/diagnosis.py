"""Figures of the diagnosis: each found effect's signature in the residuals, before and after."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")  # files only: the workstation may have no display

import matplotlib.pyplot as plt  # noqa: E402

if TYPE_CHECKING:
    from robocal.solver.diagnosis_report import EffectFigure


def effect_figure(series: EffectFigure, path: Path) -> Path:
    """One PNG: residual signature against the effect's variable, before and after, with the fitted law."""
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4), sharey=True, constrained_layout=True)
    for ax, y, title in (
        (ax0, series.before, "before: fitted without it"),
        (ax1, series.after, "after: with " + series.label),
    ):
        ax.scatter(series.x, y, s=14, alpha=0.7, label="residual per pose")
        if ax is ax0:
            ax.scatter(
                series.x,
                series.expected,
                s=10,
                marker="x",
                color="red",
                label="fitted effect, less what geometry absorbs",
            )
        ax.axhline(0.0, color="grey", lw=0.8)
        ax.set_title(title)
        ax.set_xlabel(series.x_label)
        ax.grid(alpha=0.3)
    ax0.set_ylabel(series.y_label)
    ax0.legend(loc="best", fontsize=8)
    fig.suptitle(f"{series.label}: what the geometric model missed")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_figures(figures: list[EffectFigure], report_path) -> list[Path]:
    """PNG files beside the report, one per found effect, named after the report and the effect."""
    report_path = Path(report_path)
    report_path.parent.mkdir(parents=True, exist_ok=True)
    out = []
    for i, series in enumerate(figures, start=1):
        stem = series.label.replace("(", "_").replace(")", "").replace(",", "_").replace("=", "")
        # a label's words ("2, its link's masses fitted"): a file name needs no quoting
        stem = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]+", "_", stem)).strip("_")
        out.append(
            effect_figure(series, report_path.with_name(f"{report_path.stem}_{i}_{stem}.png"))
        )
    return out
