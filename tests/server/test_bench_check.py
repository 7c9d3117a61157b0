"""`robocal bench check` prints its figures as JSON: on three arms, 210 clean checks and nine
histories of each kind of change (tracker bump, joint zero slip, payload, warming), the false
`recalibrate` rate, the delay to it and the cause named."""

from __future__ import annotations

import json

import pytest

from tests.server.test_cli import robocal


@pytest.fixture(scope="module")
def doc(tmp_path_factory):
    """`robocal bench check`'s JSON (its on_the_cell block is the second test's run, not done
    again in process)."""
    r = robocal("bench", "check", cwd=tmp_path_factory.mktemp("bench_check"))
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_checks_rarely_false_alarm_and_find_each_change_within_two(doc):
    s = doc["summary"]
    print(json.dumps({k: v for k, v in s.items() if k != "changes"}))
    assert s["clean_checks"] >= 200 and s["false_recalibrate_rate"] <= 0.01, s
    for kind, c in s["changes"].items():
        print(kind, {k: v for k, v in c.items() if k != "named"}, c["named"])
        assert c["histories"] >= 9 and c["median_delay_checks"] <= 2, (kind, c)
        if c["named_right"] is not None:  # the kinds a check can name
            assert c["named_right"] >= 0.8 * c["histories"], (kind, c)
    assert {a["arm"] for a in doc["arms"]} == {"irb2600", "kuka-like", "random"}
    d = doc["durations"]
    assert d["check_campaign_simulated_s"] < d["calibration_campaign_simulated_s"]
    cell = doc["on_the_cell"]
    assert cell["check"]["campaign_simulated_s"] < cell["target_check_s"], cell


def test_a_check_on_the_cell_takes_under_two_minutes_and_a_recalibration_far_more(doc):
    """On the simulated cell, through acquire: the 6 planned check poses at the paper's 10 s
    pause, against the default 100-pose campaign (simulated time, not wall: no timed test);
    bench check's on_the_cell()."""
    cell = doc["on_the_cell"]
    print(json.dumps(cell))
    check, full = cell["check"], cell["recalibration"]
    assert check["poses"] == 6 and check["verdict"] == "ok", check
    assert check["campaign_simulated_s"] < cell["target_check_s"]
    assert check["campaign_simulated_s"] < full["campaign_simulated_s"] / 5
