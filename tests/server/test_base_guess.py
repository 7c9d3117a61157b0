"""A cell whose `base` says the arm hangs from the ceiling while the data shows it standing: the
base is found from the data (the fit holds) and the parameter table showed "+179.99 deg" from
nominal, nothing said. The verdict warns that the data places the arm elsewhere than the cell."""

import json

from robocal.server.cli import main

TARGETS = {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]}
CEILING = [[1, 0, 0, 1500.0], [0, -1, 0, 200.0], [0, 0, -1, 2500.0], [0, 0, 0, 1]]


def test_a_base_far_from_the_cells_guess_is_said(tmp_path):
    ceiling, floor = tmp_path / "ceiling.json", tmp_path / "floor.json"
    ceiling.write_text(json.dumps({"robot": "irb2600", "targets": TARGETS, "base": CEILING}))
    floor.write_text(json.dumps({"robot": "irb2600", "targets": TARGETS}))
    said = {}
    for sim in (ceiling, floor):  # the data: hung as the cell says, then standing
        meas, model = str(tmp_path / "meas.csv"), str(tmp_path / "model.json")
        args = ["simulate", "--cell", str(sim), "--poses", "30", "--seed", "5", "--out", meas]
        assert main(args) == 0
        args = ["calibrate", meas, "--cell", str(ceiling), "--method", "ls-sum", "--out", model]
        assert main(args) == 0
        v = json.loads(open(model).read())["validation"]
        said[sim.stem] = [w for w in v["warnings"] if "from the cell's base" in w]
        assert v["deployable"] is True, v  # the fit holds: the base is the data's
    assert said["ceiling"] == []
    (line,) = said["floor"]
    assert "180.0 deg from the cell's base" in line and "check the cell's base" in line, line
