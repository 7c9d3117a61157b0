"""`robocal calibrate / evaluate / diagnose` on a file with x = 1e308: one line, non-zero exit,
at once (the parser may refuse it, else the solver's finite checks do; never a hang)."""

from __future__ import annotations

import pytest

from robocal.server.cli import main as robocal
from tests import cli_process

LIMIT_S = 120  # a hang would be a regression: the test fails instead of waiting


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("huge")
    good, bad = d / "meas.csv", d / "huge.csv"
    assert robocal(["simulate", "--poses", "30", "--seed", "3", "--out", str(good)]) == 0
    lines = good.read_text().splitlines()
    fields = lines[1].split(",")
    fields[8] = "1e308"  # x of the first reading
    lines[1] = ",".join(fields)
    bad.write_text("\n".join(lines) + "\n")
    model = d / "model.json"
    assert robocal(["calibrate", str(good), "--method", "ls-sum", "--out", str(model)]) == 0
    return d, bad, model


@pytest.mark.parametrize("command", ["calibrate", "evaluate", "diagnose"])
def test_a_huge_coordinate_exits_with_one_line(files, command):
    d, bad, model = files
    args = {
        "calibrate": ["calibrate", str(bad), "--out", str(d / "out.json")],
        "evaluate": ["evaluate", str(model), str(bad)],
        "diagnose": ["diagnose", str(bad), "--out", str(d / "report.json")],
    }[command]
    run = cli_process.run(*args, cwd=d, timeout=LIMIT_S)
    print(f"\n{command}: exit {run.returncode}: {run.stderr.strip()}")
    assert run.returncode != 0
    assert run.stderr.startswith("robocal: error:") and len(run.stderr.splitlines()) == 1, (
        run.stderr
    )
    assert "huge.csv" in run.stderr and ("1e+308" in run.stderr or "1e308" in run.stderr)
    assert not (d / "out.json").exists() and not (d / "report.json").exists()
