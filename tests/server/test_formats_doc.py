"""docs/formats.md is the generated page, and its CSV columns are what the readers demand."""

import pytest

from robocal.server.formats import formats_doc
from robocal.server.formats.campaign_csv import read_campaign, read_poses, write_predictions
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.errors import InputError
from robocal.server.formats.joints_csv import read_joints
from robocal.server.formats.targets_csv import read_targets

CELL = default_cell()
ROBOT = CELL.robot
TARGET = next(iter(CELL.targets))
VALUES = {"pose": "1", "target": TARGET, "x": "1000", "y": "0", "z": "1200"}
READERS = {
    "meas.csv": lambda p: read_campaign(p, ROBOT),
    "poses.csv": lambda p: read_poses(p, ROBOT),
    "targets.csv": lambda p: read_targets(p, ROBOT, [TARGET]),
    "joints.csv": lambda p: read_joints(p, ROBOT),
}


def test_the_page_is_the_generated_one():
    assert formats_doc.PAGE.read_text(encoding="utf-8") == formats_doc.generated(), (
        "docs/formats.md is stale: python -m robocal.server.formats.formats_doc"
    )


def columns(names):
    """The page's columns as a file has them (q1..qN spelt out for the robot)."""
    out = []
    for c in names:
        out += [f"q{i}" for i in range(1, ROBOT.n_joints + 1)] if c == formats_doc.JOINTS else [c]
    return out


def write(path, names):
    path.write_text(",".join(names) + "\n" + ",".join(VALUES.get(c, "0") for c in names) + "\n")


@pytest.mark.parametrize("f", [f for f in formats_doc.CSV_FILES if f.name in READERS])
def test_each_required_column_is_required_by_the_reader(tmp_path, f):
    read = READERS[f.name]
    required = columns(f.required)
    write(tmp_path / "ok.csv", required)
    read(tmp_path / "ok.csv")  # the required columns alone suffice
    write(tmp_path / "all.csv", required + columns(f.optional))
    read(tmp_path / "all.csv")  # and the optional ones are accepted
    for c in required:
        write(tmp_path / "less.csv", [x for x in required if x != c])
        with pytest.raises(InputError, match=rf"'{c}'"):
            read(tmp_path / "less.csv")


def test_pred_csv_has_the_documented_columns(tmp_path):
    import numpy as np

    (pred,) = [f for f in formats_doc.CSV_FILES if f.name == "pred.csv"]
    write_predictions(tmp_path / "pred.csv", ["1"], [TARGET], np.zeros((1, 1, 3)))
    header = (tmp_path / "pred.csv").read_text().splitlines()[0].split(",")
    assert header == columns(pred.required)
