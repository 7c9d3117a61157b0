"""The diagnosis's effect figures chain (geometry -> each effect in turn -> the final model) when
a richer variant replaces an accepted effect: on a UR10-like arm with a joint-2 compliance and a
joint-3 periodic error the compliance's masses were fitted after the periodic term was accepted,
and the report said compliance 0.4836 -> 0.0180 mm (the final figure, the periodic term's gain
included) beside periodic 0.0565 -> 0.0259 (of the simpler model)."""

import json

from robocal.server.cli import main

DH = [(0, 127.3, 90), (-612, 0, 0), (-572.3, 0, 0), (0, 163.941, 90), (0, 115.7, -90), (0, 92.2, 0)]
UR10_4 = {
    "robot": {
        "name": "ur10like",
        "convention": "dh",
        "joints": [
            {"a": a, "d": d, "theta": 0, "alpha": al, "limits": [-360, 360]} for a, d, al in DH
        ],
    },
    "targets": {"A": [60, 0, 35], "B": [0, 60, 35], "C": [-60, 0, 35], "D": [0, -60, 35]},
}


def test_effect_figures_chain_when_a_richer_variant_replaces_one(tmp_path, capsys):
    cell, meas, out = tmp_path / "cell.json", tmp_path / "m.csv", tmp_path / "r.json"
    cell.write_text(json.dumps(UR10_4))
    sim = ["simulate", "--cell", str(cell), "--poses", "80", "--seed", "8", "--out", str(meas)]
    effects = ["--effect", "joint_compliance:2=2", "--effect", "joint_periodic:3:1=0.01"]
    assert main([*sim, *effects]) == 0
    assert main(["diagnose", str(meas), "--cell", str(cell), "--out", str(out)]) == 0
    capsys.readouterr()
    r = json.loads(out.read_text())
    steps = [(e["holdout_rmse_before_mm"], e["holdout_rmse_after_mm"]) for e in r["effects"]]
    print(r["baseline"]["holdout_rmse_mm"], steps, r["final"])
    assert "masses fitted" in r["final"]["model"] and len(steps) == 2
    # in the order they chain: geometry's figure first, the final model's last
    steps.sort(key=lambda s: -s[0])
    assert steps[0][0] == r["baseline"]["holdout_rmse_mm"]
    assert steps[0][1] == steps[1][0] and steps[1][1] == r["final"]["holdout_rmse_mm"]
    for e in r["effects"]:  # the evidence and the gain interval are of the figures shown
        lo, hi = e["holdout_gain_interval_mm"]
        assert lo < e["holdout_rmse_before_mm"] - e["holdout_rmse_after_mm"] < hi
        assert f"from {e['holdout_rmse_before_mm']:.4f} to" in e["evidence"]
