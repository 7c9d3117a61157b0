"""One numbering of effects: effect N is the report's N-th (1-based, its ranking), its figure
REPORT_N_*.png, and `diagnose` prints it as "effect N"."""

import json
import re

from .test_cli import robocal


def test_output_report_and_figures_number_effects_alike(tmp_path):
    r = robocal(
        "simulate", "--poses", 120, "--seed", 3, "--out", "e.csv",
        "--effect", "joint_compliance:2", "--effect", "joint_periodic:3:1", "--effect", "base_shift",
        cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    r = robocal("diagnose", "e.csv", "--out", "rep/report.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    effects = json.loads((tmp_path / "rep" / "report.json").read_text())["effects"]
    assert len(effects) >= 2  # else the numbering tells nothing
    printed = re.findall(r"^effect (\d+): (\w+)", r.stdout, re.M)
    assert printed == [(str(n), e["name"]) for n, e in enumerate(effects, start=1)]
    for n, e in enumerate(effects, start=1):
        assert e["figure"].startswith(f"report_{n}_{e['name']}"), (n, e["figure"])
    on_disk = sorted(p.name for p in (tmp_path / "rep").glob("report_*.png"))
    assert on_disk == sorted(e["figure"] for e in effects)
