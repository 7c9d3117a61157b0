"""A simulated campaign (`robocal acquire`) on a cell whose `base` hangs the arm from a ceiling
measured nothing (12 poses, 0 readings, 36 missing: the virtual tracker stood where the seed put
it, the plan aimed it where the cell says); the virtual cell now stands as the cell describes."""

import json

from robocal.server.cli import main

from .test_mounted_sim import CEILING, TARGETS


def test_a_ceiling_cell_is_measured(tmp_path, capsys):
    cell, db = tmp_path / "cell.json", tmp_path / "acq.db"
    cell.write_text(json.dumps({"robot": "irb2600", "targets": TARGETS, "base": CEILING}))
    assert main(["acquire", "--db", str(db), "--poses", "12", "--cell", str(cell)]) == 0
    out = capsys.readouterr().out
    assert "36 readings, 0 missing" in " ".join(out.split()), out
    model = tmp_path / "model.json"
    args = ["calibrate", str(db), "--campaign", "1", "--cell", str(cell), "--method", "ls-sum"]
    assert main([*args, "--out", str(model)]) == 0
    assert json.loads(model.read_text())["validation"]["deployable"] is True
