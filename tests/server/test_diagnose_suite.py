"""Issue 10's harder suite: hidden effects drawn from seeds on harder campaigns, scored in process.

Requirements (not tuned to pass): at least 90% of hidden effects named with their joint and
harmonic, nothing named on clean campaigns, median final held-out RMS at most 1.2x the achievable
floor (outlier cases 1.5x), out-of-vocabulary effects named only when they pay off on a separate
test campaign, and at most 1% false alarms over 200 clean campaigns (in a pool of 2).
"""

import json

import numpy as np
import pytest

from robocal.server.bench.diagnose_suite import (
    KINDS,
    PROBE_FIT,
    PROBE_POSES,
    SIZES,
    draw_case,
    is_named,
    run_case,
    suite,
    summarize,
)
from robocal.server.formats.cell_json import Cell, cell_to_json
from robocal.solver.problem import Problem
from tests.server.test_diagnose import robocal

SEEDS = range(40)  # the ten kinds in turn, four seeds each
CLI_SEEDS = (1, 12, 20)  # compliance with outliers / periodic / clean, through the commands


@pytest.fixture(scope="module")
def results():
    return [run_case(draw_case(seed, kind)) for seed, kind in suite(SEEDS)]


@pytest.fixture(scope="module")
def summary(results):
    s = summarize(results)
    print(json.dumps(s, indent=1))  # the figures, shown with -s or on failure
    return s


def test_cases_are_reproducible_and_cover_the_issue():
    """Same seed, same case; over the suite every size, noise range and campaign defect appears."""
    a, b = draw_case(3, "joint_scale"), draw_case(3, "joint_scale")
    assert a.describe() == b.describe() and a.specs[0].startswith("joint_scale:")
    cases = [draw_case(seed, kind, aim=False) for seed, kind in suite(range(80))]
    assert {c.n_poses for c in cases} == set(SIZES)
    assert {c.robot.name.split("-")[0] for c in cases} >= {"irb2600", "kuka", "random"}
    assert {len(c.targets) for c in cases} >= {1, 2, 3, 4}
    noise = [c.options["noise_scale"] for c in cases]
    assert min(noise) < 1.5 and max(noise) > 5.0
    for key in ("arm_scatter_deg", "targets_per_pose", "beam_break_rate", "outlier_rate"):
        assert 0.1 * len(cases) <= sum(key in c.options for c in cases) < 0.6 * len(cases), key
    assert {k for c in cases for k in [c.kind]} == set(KINDS)
    two = draw_case(7, "compliance_2_3", aim=False)
    assert [h[:2] for h in two.hidden] == [("joint_compliance", 2), ("joint_compliance", 3)]


def test_aimed_magnitude_shows_the_drawn_multiple():
    """On a fresh noisy campaign a geometric fit errs held out by the drawn multiple of the floor."""
    from robocal.solver.calibrate import calibrate
    from robocal.solver.kinematics import predict

    case = draw_case(3, "joint_scale")
    vc = case.cell()
    opts = {
        "noise_scale": case.options["noise_scale"],
        "arm_scatter_deg": case.options.get("arm_scatter_deg", 0.0),
    }
    meas = vc.campaign(PROBE_POSES, case.cell_seed + 5, **opts)
    last = vc.last_campaign
    floor = np.hypot(last["noise_floor_mm"], last.get("arm_scatter_rms_mm", 0.0))
    names = meas.target_names
    nominal = np.array([case.targets[t] for t in names])
    fit = calibrate(
        Problem(case.robot, nominal, names, meas.q[:PROBE_FIT], meas.xyz[:PROBE_FIT]), "ls-sum"
    )
    err = predict(fit.layout, fit.x, meas.q[PROBE_FIT:]) - meas.xyz[PROBE_FIT:]
    ratio = np.sqrt(np.nanmean(np.sum(err**2, axis=-1))) / floor
    assert ratio == pytest.approx(case.multiples[0], rel=0.3)


def test_hidden_effects_are_named(summary):
    det = summary["detection"]
    assert det["rate"] >= 0.9, det


def test_clean_campaigns_name_nothing(results):
    alarms = [r["case"] for r in results if "skipped" not in r and r["false_alarm"]]
    assert not alarms, alarms


def test_small_campaigns_named_right_are_seldom_in_doubt(summary):
    """Resampled small campaigns whose hidden effects were all named are in doubt at most one time
    in ten (the doubt is for answers a few poses decide, not noise); clean ones name nothing, so
    are never resampled."""
    d = summary["doubt"]
    right = d["effect_all_named"]
    assert right["resampled"] > 0 and 10 * right["in_doubt"] <= right["resampled"], d
    assert d["clean"] == {"resampled": 0, "in_doubt": 0}, d


def test_final_error_is_near_the_achievable_floor(summary):
    assert summary["holdout_over_floor"]["median"] <= 1.2, summary["holdout_over_floor"]
    outliers = summary["holdout_over_floor_outlier_cases"]
    if outliers["count"]:
        assert outliers["median"] <= 1.5, outliers


def test_out_of_vocabulary_named_only_when_it_pays_off(results, summary):
    oov = [r for r in results if r["case"]["kind"] == "out_of_vocabulary"]
    if all("skipped" in r for r in oov):
        pytest.skip(oov[0]["skipped"])
    unpaid = [
        (r["case"], r["named"], r.get("payoff"))
        for r in oov
        if "skipped" not in r and r["named"] and not r["payoff"]["pays_off"]
    ]
    assert not unpaid, unpaid


def test_payoff_compares_the_named_model_with_geometry_on_other_poses():
    """A real effect named pays off on a separate campaign of the same cell, against geometry."""
    from robocal.server.bench.diagnose_suite import _diagnoser, payoff
    from robocal.solver.diagnose import diagnose

    case = draw_case(2, "joint_periodic")
    vc = case.cell()
    meas = vc.campaign(case.n_poses, case.cell_seed, **case.options)
    nominal = np.array([case.targets[t] for t in meas.target_names])
    d = diagnose(Problem.of(case.robot, nominal, meas))
    assert d.extensions, "premise: the effect is named"
    p = payoff(case, vc, _diagnoser(case, meas, meas.xyz), d)
    assert p["pays_off"] and p["named_rmse_mm"] < 0.7 * p["geometric_rmse_mm"], p


@pytest.mark.parametrize("seed", CLI_SEEDS)
def test_through_the_command_line(tmp_path, results, seed):
    """`robocal simulate` with the suite's flags, then `robocal diagnose`, as in process."""
    kind = suite([seed])[0][1]
    case = draw_case(seed, kind)
    assert not case.skip
    (tmp_path / "cell.json").write_text(json.dumps(cell_to_json(Cell(case.robot, case.targets))))
    robocal(
        "simulate",
        "--cell",
        "cell.json",
        *case.simulate_args(),
        "--out",
        "meas.csv",
        "--truth-out",
        "truth.json",
        cwd=tmp_path,
    )
    robocal("diagnose", "meas.csv", "--cell", "cell.json", "--out", "report.json", cwd=tmp_path)
    report = json.loads((tmp_path / "report.json").read_text())
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert len(truth["campaign"]["outliers"]) == results[seed]["outliers"]
    named = [(e["name"], e.get("joint"), e.get("harmonic")) for e in report["effects"]]
    assert [list(n) for n in named] == results[seed]["named"]  # the CSV's rounding changes nothing
    assert report["final"]["holdout_rmse_mm"] == pytest.approx(
        results[seed]["final_holdout_rmse_mm"], rel=0.05
    )
    for hidden in case.hidden:
        assert is_named(hidden, named), (case.specs, named)
    if kind == "clean":
        assert named == []


def test_false_alarms_over_200_clean_campaigns():
    """At most 1% of clean campaigns (sizes, noise, scatter, defects all drawn) name any effect."""
    from robocal.server.bench.diagnose import run_suite

    runs = run_suite([(seed, "clean") for seed in range(1000, 1200)], workers=2)
    alarms = [r["case"]["seed"] for r in runs if r["false_alarm"]]
    assert len(alarms) <= 2, alarms


def test_bench_reports_the_suite_and_the_timing():
    """The bench JSON: detection per effect and size, false alarms, held-out/floor ratios, time."""
    from robocal.server.bench.diagnose import run_diagnose_bench

    out = run_diagnose_bench(effect_cases=2, clean_cases=1, sizes=(30,), workers=1, split_cases=1)
    json.dumps(out)
    s = out["summary"]
    assert out["effect_cases"] == 2 and len(out["cases"]) == 3
    assert s["detection"]["hidden"] == 2 and set(s["detection"]["per_effect"]) == {
        "joint_compliance",
        "joint_periodic",
    }
    assert s["false_alarms"]["clean_campaigns"] == 1
    doubt = s["doubt"]
    assert set(doubt) == {"clean", "effect_all_named", "effect_missed"}
    assert sum(d["resampled"] for d in doubt.values()) == sum(r["resampled"] for r in out["cases"])
    assert s["holdout_over_floor"]["count"] + s["holdout_over_floor_outlier_cases"]["count"] == 3
    split = out["configuration_split"]["summary"]
    assert split["cases"] == 1 and split["clean_cases"] == 1 and len(out["split_cases"]) == 1
    case = out["split_cases"][0]
    assert case["case"]["split"] in ("elbow", "wrist") and case["floor_mm"] > 0
    assert case["ratio"] == case["diagnosed_test_mm"] / case["geometric_test_mm"]
    assert out["configuration_split"]["real"] == []  # no real campaigns asked for
    t = out["timing"]["30"]
    assert t["seconds"] > 0 and t["target_seconds"] is None and t["met"] is None
    assert set(out["met"]) >= {
        "detection_rate_min_0.9",
        "false_alarm_rate_max_0.01",
        "holdout_over_floor_median_max_1.2",
        "seconds_30_poses",
        "split_never_worse_than_geometry_1.02",
    }


def test_a_richer_compliance_does_not_stand_in_for_the_next_joints():
    """Joint 2 and 3 compliance on 40 poses (seed 24): joint 2's compliance with its driven link's
    masses fitted beats one stiffness alone, but one stiffness with joint 3's compliance does as
    well; the richer variant would have taken joint 3's share and left it unnamed."""
    r = run_case(draw_case(24, "compliance_2_3"))
    assert r["case"]["poses"] == 40
    named = sorted(tuple(n) for n in r["named"])
    assert named == [("joint_compliance", 2, None), ("joint_compliance", 3, None)], named
