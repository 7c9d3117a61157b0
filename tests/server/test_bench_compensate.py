"""`robocal bench compensate` times the batched solve next to scipy's one target at a time."""

from robocal.server.bench.compensate import run_compensate_bench


def test_bench_reports_throughput_next_to_the_reference():
    r = run_compensate_bench(sizes=(20,), reference_max=3)
    rows = r["with_starting_guess"]
    assert [(x["targets"], x["smrs_per_target"]) for x in rows] == [(20, 1), (20, 3)]
    for x in rows:
        assert x["targets_per_second"] > 0 and x["reference"]["targets"] == 3
        assert x["worst_predicted_error_mm"] < 0.01
        assert x["reference"]["worst_predicted_error_mm"] < 0.01
    cf = r["from_configuration"]
    assert cf["worst_predicted_error_mm"] < 0.01 and cf["configuration_kept"] == cf["targets"]
    assert cf["max_joint_change_deg"] < 1.0
