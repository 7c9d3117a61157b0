"""`robocal bench compensate` times the batched solve next to scipy's one target at a time, with
the same Jacobian, tolerance and error measure, in interleaved rounds."""

import math

import numpy as np

from robocal.server.bench.compensate import miss_mm, run_compensate_bench


def test_bench_reports_throughput_next_to_the_peers():
    r = run_compensate_bench(sizes=(8,), rounds=2)
    (row,) = r["with_starting_guess"]
    assert row["targets"] == 8 and row["smrs_per_target"] == 3 and row["rounds"] == 2
    assert len(r["load_average"]["start"]) == 3 and len(row["load_average"]["after"]) == 3
    assert set(row["timings"]) == {"ours", "peer_trf", "peer_lm"}
    for t in row["timings"].values():
        assert t["runs"] == 2 and 0 < t["min_s"] <= t["median_s"] <= t["max_s"]
    speedup = row["headline"]["speedup"]
    assert row["headline"]["peer"] in ("peer_trf", "peer_lm") and speedup["rounds"] == 2
    assert all(math.isfinite(speedup[k]) and speedup[k] > 0 for k in ("min", "median", "max"))
    # both sides reach the same joints and the same miss, measured alike
    assert row["converged"] == 8
    for k in ("peer_trf", "peer_lm"):
        assert row[k]["max_joint_difference_from_ours_deg"] < 1e-5
        assert row[k]["outside_limits"] == 0
        assert abs(row["miss_mm"][k]["max"] - row["miss_mm"]["ours"]["max"]) < 1e-6
    assert row["miss_mm"]["ours"]["max"] < 0.01
    cf = r["from_configuration"]
    assert cf["worst_miss_mm"] < 0.01 and cf["configuration_kept"] == cf["targets"]
    assert cf["max_joint_change_deg"] < 1.0


def test_miss_is_the_rms_over_the_masked_smrs():
    class Model:
        def predict(self, q):
            return np.zeros((len(q), 3, 3))

    desired = np.zeros((2, 3, 3))
    desired[0, 0] = [3.0, 4.0, 0.0]  # 5 mm off on one of two SMRs: RMS sqrt(25 / 2)
    desired[0, 2] = [100.0, 0.0, 0.0]  # not in the mask
    mask = np.array([[True, True, False], [True, True, True]])
    assert np.allclose(miss_mm(Model(), np.zeros((2, 6)), desired, mask), [np.sqrt(12.5), 0.0])
