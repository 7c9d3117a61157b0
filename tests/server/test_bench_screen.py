"""`robocal bench outliers` counts false flags and outliers found over drawn campaigns."""

from robocal.server.bench.screen import run_screen_bench


def test_bench_counts_flags_and_finds():
    r = run_screen_bench(clean=6, dirty=4)
    assert r["clean"]["campaigns"] == 6 and r["clean"]["with_a_false_flag"] <= 1
    d = r["dirty"]
    assert d["outliers"] > 0 and d["found"] + len(d["missed"]) == d["outliers"]
    assert d["found"] >= 0.8 * d["outliers"]
