"""`robocal diagnose` says what it leaves unexplained: a campaign whose arm hides a wrist coupling
(outside the vocabulary, drawn from a seed) prints the block with the coupling's covariate first,
and the report holds the same block."""

import json
import subprocess
import sys
from pathlib import Path

from robocal.server.formats.campaign_csv import write_campaign
from robocal.server.formats.cell_json import cell_to_json, default_cell
from tests.solver.test_unexplained import campaign, draw

ROOT = Path(__file__).resolve().parents[2]


def test_diagnose_prints_the_unexplained_block(tmp_path):
    effect, name, channel = draw(1)
    _, _, meas = campaign(1, effect)
    write_campaign(tmp_path / "meas.csv", meas)
    (tmp_path / "cell.json").write_text(json.dumps(cell_to_json(default_cell())))
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "robocal.server.cli",
            "diagnose",
            "meas.csv",
            "--cell",
            "cell.json",
            "--out",
            "report.json",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={"COLUMNS": "200", "PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert r.returncode == 0, r.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    block = report["unexplained"]
    from robocal.server.formats.report_doc import ReportDoc

    assert (
        ReportDoc.model_validate(report).unexplained.covariates[0].name
        == block["covariates"][0]["name"]
    )
    top = block["covariates"][0]
    assert (top["name"], top["channel"]) == (name, channel)
    lines = r.stdout.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("Unexplained: "))
    assert f"{block['holdout_rmse_mm']:.3f} mm held out" in lines[first]
    assert lines[first + 1].strip().startswith(f"{top['strength']:.2f}  {name}: "), lines[first + 1]
    assert "per pose:" in r.stdout
