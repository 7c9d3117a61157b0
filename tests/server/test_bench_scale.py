"""`robocal bench scale`: the calibrate process next to np.loadtxt of the same file and a
read-and-fit-only process, each figure with its runs, and the targets' ratios."""

from __future__ import annotations

import json

import pytest

from robocal.server.bench.scale import run_calibrate_scale


@pytest.fixture(scope="module")
def bench():
    return run_calibrate_scale(poses=300, repeats=2)


def test_every_process_has_its_runs_and_memory(bench):
    assert bench["poses"] == 300 and bench["readings"] == 900
    for name in ("calibrate", "loadtxt", "fit_only"):
        p = bench["process"][name]
        assert len(p["wall_seconds"]["runs"]) == 2
        s = p["wall_seconds"]
        assert s["min"] <= s["median"] <= s["max"]
        assert p["peak_rss_mb"]["median"] > 0
    # the launcher's own memory does not leak into the figures: numpy alone is far smaller
    assert (
        bench["process"]["loadtxt"]["peak_rss_mb"]["max"]
        < (bench["process"]["calibrate"]["peak_rss_mb"]["min"])
    )
    assert len(bench["load_average_1_5_15"]["start"]) == 3
    json.dumps(bench)  # printable as it is


def test_the_whole_command_holds_the_fit_and_the_ratios_are_its(bench):
    inside = bench["in_process"]
    assert inside["calibrate_peak_mb"] >= inside["fit_peak_mb"] > 0
    t = bench["targets"]
    assert t["calibrate_over_fit_peak_tracemalloc"]["value"] == inside["calibrate_over_fit"]
    wall = bench["process"]
    ratio = wall["calibrate"]["wall_seconds"]["median"] / wall["loadtxt"]["wall_seconds"]["median"]
    assert t["calibrate_over_loadtxt_wall"]["value"] == pytest.approx(ratio)
    assert t["calibrate_over_loadtxt_wall"]["max"] == 6.0
    assert t["calibrate_over_fit_peak_rss"]["max"] == 1.5
