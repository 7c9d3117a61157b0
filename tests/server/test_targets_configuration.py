"""targets.csv's configuration columns (cf1, cf4, cf6, cfx) as the reader takes or refuses them."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.server.formats.errors import InputError
from robocal.server.formats.targets_csv import read_targets
from robocal.solver.robot import IRB2600
from tests.robots import IIWA_LIKE

HEAD = "pose,target,x,y,z"


def targets(tmp_path, header: str, *rows: str):
    path = tmp_path / "targets.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def test_confdata_per_pose_and_blank_where_joints_are_given(tmp_path):
    path = targets(
        tmp_path,
        f"{HEAD},q1,q2,q3,q4,q5,q6,cf1,cf4,cf6,cfx",
        "1,A,1000,0,900,,,,,,,-1,2,-3,5",
        "1,B,1000,50,900,,,,,,,-1,2,-3,5",
        "2,A,1000,0,900,0,0,0,0,10,0,,,,",
    )
    t = read_targets(path, IRB2600, ("A", "B"))
    assert t.cf is not None
    np.testing.assert_array_equal(t.cf[0], [-1, 2, -3, 5])
    assert np.isnan(t.cf[1]).all() and np.isnan(t.q0[0]).all()


@pytest.mark.parametrize(
    "header,row,where",
    [
        (f"{HEAD},cf1,cf4,cf6", "1,A,1,2,3,0,0,0", "targets.csv:1: missing column 'cfx'"),
        (f"{HEAD},cf1,cf4,cf6,cfx", "1,A,1,2,3,3,0,0,0", "targets.csv:2:6: column 'cf1': 3 is not"),
        (f"{HEAD},cf1,cf4,cf6,cfx", "1,A,1,2,3,0,,0,0", "targets.csv:2:7: column 'cf4': empty"),
        (f"{HEAD},cf1,cf4,cf6,cfx", "1,A,1,2,3,0,0,0,-1", "targets.csv:2:9: column 'cfx': -1 is"),
    ],
)
def test_bad_confdata_is_refused_naming_the_field(tmp_path, header, row, where):
    with pytest.raises(InputError) as e:
        read_targets(targets(tmp_path, header, row), IRB2600, ("A",))
    assert str(e.value).startswith(str(tmp_path / where)), str(e.value)


def test_a_seven_axis_arm_has_no_confdata(tmp_path):
    path = targets(tmp_path, f"{HEAD},cf1,cf4,cf6,cfx", "1,A,1,2,3,0,0,0,0")
    with pytest.raises(InputError, match=r"targets.csv:1: column 'cf1': .* iiwa-like has 7 joints"):
        read_targets(path, IIWA_LIKE, ("A",))
