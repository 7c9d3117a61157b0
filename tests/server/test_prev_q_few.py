"""prev_q in radians beside q in degrees on files of one or two poses, where no spread can be
judged: each pose's own joints tell (read as radians the arm came from near the pose, read as
degrees from far), and degrees are never taken for radians. On the real campaigns, prev_q the
previous pose's joints (they visit their poses in a tour: 10-63 deg between poses)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from robocal.server.formats.campaign_csv import read_campaign, write_campaign
from robocal.server.formats.cell_json import read_cell
from robocal.server.formats.errors import InputError
from tests.real import REAL

WINDOWS = 40  # files cut from each campaign's first poses


def _files(tmp_path, name: str, poses: int, prev_of):
    """(path, robot) of each `poses`-pose file cut from a real campaign, prev_q prev_of(the
    previous poses' joints (rad), the window's) as the fields' numbers read in degrees."""
    cell = read_cell(REAL / name / "cell.json")
    meas = read_campaign(REAL / name / "train.csv", cell.robot)
    meas = replace(meas, prev_q=np.vstack([np.full((1, meas.q.shape[1]), np.nan), meas.q[:-1]]))
    for k, start in enumerate(range(1, meas.n_poses - poses + 1, poses)[:WINDOWS]):
        part = meas.subset(np.arange(start, start + poses))
        path = tmp_path / f"{name}_{k}.csv"
        write_campaign(path, replace(part, prev_q=prev_of(part.prev_q, part)))
        yield path, cell.robot


@pytest.mark.parametrize("poses", [1, 2])
def test_prev_q_in_radians_on_one_or_two_poses_is_refused(tmp_path, poses):
    """Before, a file of fewer than three poses was never judged: radians passed as degrees and
    turned every backlash's approach toward zero. Judged where the arm came from a pose near
    the one it went to: the UR5's tour (10-50 deg between poses), most files; the IRB 120's and
    the QKM's random orders (94-333 deg), none: nothing there tells radians from degrees."""
    said = {}
    for name in ("ur5_jacobi", "irb120_wu", "qkm_hl6"):
        refused = total = 0
        for path, robot in _files(tmp_path, name, poses, lambda prev, _: np.deg2rad(prev)):
            total += 1
            try:
                read_campaign(path, robot)
            except InputError as e:
                msg = str(e)
                assert "column 'prev_q" in msg and "look like radians" in msg, msg
                assert msg.endswith("give them in degrees") and "\n" not in msg
                refused += 1
        said[name] = (refused, total)
    print(f"\n{poses}-pose files with prev_q in radians refused (of): {said}\n{msg}")
    refused, total = said["ur5_jacobi"]
    assert refused >= 0.4 * total


def test_joints_in_radians_beside_prev_q_in_degrees_on_one_pose_are_named(tmp_path):
    path, robot = next(_files(tmp_path, "ur5_jacobi", 1, lambda prev, _: prev))
    text = path.read_text().splitlines()
    header = text[0].split(",")
    rows = []
    for line in text[1:]:
        f = line.split(",")
        for i in range(1, robot.n_joints + 1):
            c = header.index(f"q{i}")
            f[c] = f"{np.radians(float(f[c])):.6f}"
        rows.append(",".join(f))
    path.write_text("\n".join([text[0], *rows]) + "\n")
    with pytest.raises(InputError, match=r"column 'q\d+': .* q1..q6 look like radians"):
        read_campaign(path, robot)


@pytest.mark.parametrize("poses", [1, 2])
def test_prev_q_in_degrees_on_one_or_two_poses_passes(tmp_path, poses):
    """The previous pose's joints, home (zero joints) for one pose or all, an approach point
    beside each pose, and home jogged a few degrees: all degrees, all read."""
    rng = np.random.default_rng(1)

    def first_home(prev, _):
        out = prev.copy()
        out[0] = 0.0
        return out

    def jogged(d):
        return lambda prev, _: np.radians(rng.uniform(-d, d, size=prev.shape))

    ways = [
        lambda prev, _: prev,
        lambda prev, _: np.zeros_like(prev),
        first_home,
        lambda prev, part: part.q - np.deg2rad(2.0),
        lambda prev, _: np.radians(np.full(prev.shape, 1e-3)),
        *(jogged(d) for d in (0.5, 1.0, 2.0, 3.0)),
    ]
    read = 0
    for name in ("irb120_wu", "qkm_hl6", "ur5_jacobi"):
        for way in ways:
            for path, robot in _files(tmp_path, name, poses, way):
                read_campaign(path, robot)  # no InputError
                read += 1
    print(f"\n{read} {poses}-pose files in degrees read")
