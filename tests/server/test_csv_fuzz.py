"""Property tests: whatever bytes a CSV file holds, the readers answer data or InputError."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from robocal.server.exports.params import read_params
from robocal.server.formats import InputError, read_campaign, read_poses
from robocal.server.formats.csv_table import Table
from robocal.server.formats.joints_csv import read_joints
from robocal.solver.robot import IRB2600

from ..fuzz import FUZZ, edge_variants, mutated, random_lines

LO, HI = np.rad2deg(IRB2600.lower), np.rad2deg(IRB2600.upper)
HEADER = "pose,q1,q2,q3,q4,q5,q6,target,x,y,z,time_s,temp_c"


@st.composite
def campaigns(draw) -> str:
    """A valid meas.csv: a few poses inside the joint limits, each measured on a few SMRs."""
    rows = [HEADER]
    for pose in range(1, draw(st.integers(1, 3)) + 1):
        q = [draw(st.floats(lo, hi)) for lo, hi in zip(LO, HI, strict=True)]
        for target in draw(st.lists(st.sampled_from("ABC"), min_size=1, max_size=3, unique=True)):
            xyz = [draw(st.floats(-3000, 3000)) for _ in range(3)]
            cells = [str(pose), *(f"{v:.6f}" for v in q), target, *(f"{v:.4f}" for v in xyz)]
            rows.append(",".join([*cells, f"{pose * 1.5:.3f}", "20.5"]))
    return "\n".join(rows) + "\n"


EXAMPLE = (
    HEADER + "\n"
    "1,0,10,-20,30,-40,50,A,1000.0,200.0,1500.0,0.0,20.5\n"
    "1,0,10,-20,30,-40,50,B,1010.0,210.0,1490.0,0.5,20.5\n"
    '2,5,0,0,0,0,0,"A",990.0,-20.0,1600.0,,\n'
)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("csv")


def read_all(folder, data: bytes) -> None:
    """Every reader on this file content; InputError is the only way out."""
    path = folder / "meas.csv"
    path.write_bytes(data)
    for read in (
        lambda: read_campaign(path, IRB2600),
        lambda: read_poses(path, IRB2600),
        lambda: read_joints(path, IRB2600),
        lambda: read_params(path),
        lambda: Table.read(path),
    ):
        try:
            read()
        except InputError as e:
            assert str(e).startswith(str(path)), str(e)  # the message names the file


def test_the_example_and_generated_campaigns_are_valid(folder):
    path = folder / "valid.csv"
    path.write_text(EXAMPLE)
    assert read_campaign(path, IRB2600).xyz.shape == (2, 2, 3)


@FUZZ
@given(campaigns())
def test_generated_campaigns_read(folder, text):
    path = folder / "valid.csv"
    path.write_text(text)
    read_campaign(path, IRB2600)


@FUZZ
@given(st.binary(max_size=600))
def test_random_bytes_give_only_input_errors(folder, data):
    read_all(folder, HEADER.encode() + b"\n" + data)
    read_all(folder, data)


@FUZZ
@given(st.lists(random_lines(), max_size=4))
def test_random_lines_give_only_input_errors(folder, lines):
    read_all(folder, "\n".join([HEADER, *lines]).encode("utf-8", "surrogatepass"))


@FUZZ
@given(mutated(campaigns(), sep=","))
def test_mutated_campaigns_give_only_input_errors(folder, text):
    read_all(folder, text.encode("utf-8", "surrogatepass"))


def test_every_field_takes_every_edge_token(folder):
    header_and_first_row = "".join(EXAMPLE.splitlines(keepends=True)[:2])
    for variant in edge_variants(header_and_first_row, sep=","):
        read_all(folder, variant.encode("utf-8"))
