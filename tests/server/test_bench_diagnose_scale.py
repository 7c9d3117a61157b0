"""`robocal bench scale`'s diagnose part: each size in its own process, beside np.loadtxt."""

import pytest

from robocal.server.bench.scale import peak_rss_mib, run_diagnose_scale


def test_each_size_has_time_memory_and_the_file_reference():
    out = run_diagnose_scale(sizes=(60, 120))
    for poses in (60, 120):
        d = out[str(poses)]
        assert d["poses"] == poses
        assert d["seconds"] > 0 and d["cpu_seconds"] > 0 and d["loadtxt_seconds"] > 0
        assert d["over_loadtxt"] == pytest.approx(d["seconds"] / d["loadtxt_seconds"])
        assert d["peak_rss_mib"] >= d["rss_before_diagnosis_mib"] > 0
    ratio = out["largest_over_smallest"]
    assert ratio["poses"] == 2.0
    assert ratio["seconds"] == pytest.approx(out["120"]["seconds"] / out["60"]["seconds"])
    assert set(out["met"]) == {"seconds_linear", "peak_rss_under_1_gib"}


def test_peak_memory_is_this_process_own():
    assert 10 < peak_rss_mib() < 64 * 1024
