"""The column-wise meas.csv / poses.csv reader against the row reader: on every file it accepts,
the same numbers; on every file the row reader refuses, it declines (so the row reader names the
line). Files: the generated and mutated campaigns of the fuzz tests, every edge token in every
field, the repository's and ../shared's CSV files, and larger simulated campaigns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given

from robocal.server.formats import InputError
from robocal.server.formats.campaign_columns import read_campaign_columns, read_poses_columns
from robocal.server.formats.campaign_csv import (
    BOUNDS,
    EXTRAS,
    LIMIT_TOL_DEG,
    MEASURED,
    SAME_POSE_TOL_DEG,
    read_campaign_rows,
    read_poses_rows,
    write_campaign,
)
from robocal.server.formats.cell_json import read_cell
from robocal.server.formats.files import read_text
from robocal.solver.robot import IRB2600

from ..fuzz import FUZZ, edge_variants, mutated
from .test_csv_fuzz import EXAMPLE, campaigns

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared"


def rows_or_error(read, path, robot):
    try:
        return read(path, robot), None
    except InputError as e:
        return None, str(e)


def same(a, b) -> None:
    """Two readings equal, NaN where NaN, to the bit."""
    if isinstance(a, tuple):
        for u, v in zip(a, b, strict=True):
            same(u, v)
        return
    if hasattr(a, "xyz"):
        assert a.pose_ids == b.pose_ids and a.target_names == b.target_names
        for f in ("q", "xyz", "time_s", "temp_c"):
            same(getattr(a, f), getattr(b, f))
        return
    if a is None or b is None:
        assert a is None and b is None
    elif isinstance(a, list):
        assert a == b
    else:
        np.testing.assert_array_equal(a, b)


def agree(path, robot=IRB2600) -> str:
    """Check both readers agree on the file; 'accepted', 'refused' (both) or 'row-only'."""
    text = read_text(path)
    slow, err = rows_or_error(read_campaign_rows, path, robot)
    fast = read_campaign_columns(
        text, robot, MEASURED, EXTRAS, BOUNDS, LIMIT_TOL_DEG, SAME_POSE_TOL_DEG
    )
    if err is not None:
        assert fast is None, f"the column reader took what the row reader refuses: {err}"
    elif fast is not None:
        same(fast, slow)
    slow_p, err_p = rows_or_error(read_poses_rows, path, robot)
    fast_p = read_poses_columns(text, robot, EXTRAS, BOUNDS, LIMIT_TOL_DEG, SAME_POSE_TOL_DEG)
    if err_p is not None:
        assert fast_p is None, f"poses: the column reader took what the row reader refuses: {err_p}"
    elif fast_p is not None:
        same(fast_p, slow_p)
    if err is not None:
        return "refused"
    return "accepted" if fast is not None else "row-only"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("columns")


def write(folder, text: str) -> Path:
    path = folder / "meas.csv"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    return path


def test_the_example_is_read_column_wise(folder):
    # the example quotes a field: the row reader reads it
    assert agree(write(folder, EXAMPLE)) == "row-only"
    assert agree(write(folder, EXAMPLE.replace('"A"', "A"))) == "accepted"


@FUZZ
@given(campaigns())
def test_generated_campaigns_agree(folder, text):
    assert agree(write(folder, text)) == "accepted"


@FUZZ
@given(mutated(campaigns(), sep=","))
def test_mutated_campaigns_agree(folder, text):
    agree(write(folder, text))


def test_every_field_takes_every_edge_token(folder):
    seen = set()
    text = EXAMPLE.replace('"A"', "A")
    for variant in edge_variants(text, sep=","):
        seen.add(agree(write(folder, variant)))
    assert seen == {"accepted", "refused", "row-only"}


def test_line_ends_blank_lines_case_and_spaces(folder):
    text = EXAMPLE.replace('"A"', "A")
    lines = text.splitlines()
    variants = {
        "crlf": "\r\n".join(lines) + "\r\n",
        "no final newline": "\n".join(lines),
        "blank lines": "\n\n".join(lines) + "\n\n  \n",
        "upper-case header": text.replace("pose,q1", "POSE,Q1"),
        "spaces around fields": text.replace(",", " , "),
        "lone CR": text.replace("\n", "\r", 1),
        "tab": text.replace(",", "\t,", 1),
        "extra column": text.replace("temp_c", "temp_c,note").replace("\n1,", ",x\n1,"),
        "short row": text + "3,0,0,0,0,0,0,A,1,2\n",
        "long row": text + "3,0,0,0,0,0,0,A,1,2,3,4,5,6\n",
        "header only": lines[0] + "\n",
    }
    for name, variant in variants.items():
        outcome = agree(write(folder, variant))
        assert outcome in ("accepted", "refused", "row-only"), name
    assert agree(write(folder, variants["crlf"])) == "accepted"
    assert agree(write(folder, variants["blank lines"])) == "accepted"
    assert agree(write(folder, variants["short row"])) == "refused"
    assert agree(write(folder, variants["long row"])) == "refused"


def test_every_csv_of_the_repository_and_the_real_campaigns():
    files = [p for p in ROOT.glob("tests/**/*.csv") if ".venv" not in p.parts]
    files += sorted(SHARED.glob("data/**/*.csv"))
    assert files
    counts: dict[str, int] = {}
    for path in files:
        cell = path.parent / "cell.json"
        robot = read_cell(cell).robot if cell.exists() else IRB2600
        outcome = agree(path, robot)
        counts[outcome] = counts.get(outcome, 0) + 1
    # the real campaigns are read column-wise
    for name in ("irb120_wu", "qkm_hl6"):
        real = SHARED / "data" / "real" / name
        if real.exists():
            assert agree(real / "train.csv", read_cell(real / "cell.json").robot) == "accepted"


@pytest.mark.parametrize("beam_breaks", [0.0, 0.2])
def test_a_simulated_campaign_round_trips_column_wise(folder, beam_breaks):
    from robocal.drivers.cell import VirtualCell
    from tests.robots import TARGETS

    cell = VirtualCell.random(IRB2600, TARGETS, seed=4)
    meas = cell.campaign(2000, seed=5, beam_break_rate=beam_breaks)
    path = folder / "sim.csv"
    write_campaign(path, meas)
    assert agree(path) == "accepted"


def test_plain_decimals_from_bytes_equal_float_to_the_bit():
    from robocal.server.formats.campaign_columns import _parse_decimals

    tokens = ["0", "-0", "+7", "007.50", ".5", "5.", "-.25", "123456789012345", "0.1", "2.675"]
    tokens += [f"{v:.9f}" for v in np.random.default_rng(0).uniform(-400, 400, 200)]
    width = max(map(len, tokens))
    window = np.array([list(t.ljust(width, ",").encode()) for t in tokens], dtype=np.uint8).T
    got = _parse_decimals(window.copy(), np.array([len(t) for t in tokens]))
    want = np.array([float(t) for t in tokens])
    assert got is not None and got.tobytes() == want.tobytes()  # -0.0 too
    for refused in ("1e3", "1.2.3", "-", ".", "1 2", "--1", "1234567890123456"):
        w = np.array([list(refused.encode())], dtype=np.uint8).T
        assert _parse_decimals(w.copy(), np.array([len(refused)])) is None, refused


def test_decimals_by_words_equal_float_to_the_bit():
    """The eight-bytes-at-a-time parser (points lined up in each column) against float(), and
    its refusals (Horner's rule or the row reader then decides)."""
    from robocal.server.formats.campaign_columns import _words

    rng = np.random.default_rng(1)
    columns = [
        [f"{v:.9f}" for v in rng.uniform(-400, 400, 300)] + ["-0.000000000", "+7.000000001"],
        [f"{v:.6f}" for v in rng.uniform(-3000, 3000, 300)] + ["-.000001", "12345678.999999"],
        [str(v) for v in rng.integers(-(10**14), 10**15, 300)] + ["0", "-0", "+5", "007"],
        [f"{v:.0f}." for v in rng.uniform(0, 1e6, 300)] + ["5.", "-0."],
        [f"{v:.2f}" for v in rng.uniform(-9, 9, 300)] + ["", "1.00"],  # a blank is NaN
    ]

    def parse(column, point):
        text = "h" * 16 + "\n" + "".join(f"{t}\n" for t in column) + " " * 24
        raw = np.frombuffer(text.encode(), dtype=np.uint8)
        words = np.ndarray((len(raw) - 7,), dtype="<u8", buffer=raw, strides=(1,))
        ends = np.flatnonzero(raw == ord("\n"))
        return _words(words, ends[:-1, None] + 1, ends[1:, None], np.array([point]))

    for column in columns:
        given = next(t for t in column if t)
        got = parse(column, len(given) - given.find(".") if "." in given else -1)
        want = np.array([float(t) if t else np.nan for t in column])
        assert got is not None and got.ravel().tobytes() == want.tobytes()  # -0.0 and NaN too
    for refused in (
        ["1.5", "12.25"],
        ["1.5", "15"],
        ["1e3"],
        ["-"],
        ["."],
        ["1 2"],
        ["--1"],
        ["1234567890123456"],
        ["1.2.3"],
        ["12345678901234567"],
        ["+-1"],
        ["1-"],
    ):
        point = len(refused[0]) - refused[0].find(".") if "." in refused[0] else -1
        assert parse(refused, point) is None, refused


def test_a_pose_whose_rows_spell_its_joints_differently(folder):
    """A pose's later rows that repeat its joints in other digits (so not byte for byte) are
    read value by value: within the tolerance the same campaign, beyond it refused by both."""
    from robocal.drivers.cell import VirtualCell
    from tests.robots import TARGETS

    cell = VirtualCell.random(IRB2600, TARGETS, seed=4)
    path = folder / "sim.csv"
    write_campaign(path, cell.campaign(20, seed=5))
    lines = path.read_text().splitlines(keepends=True)
    row = lines[2].split(",")  # the first pose's second row
    assert lines[1].split(",")[0] == row[0]
    for q1, verdict in (
        (f"{float(row[1]):.4f}", "accepted"),
        (f"{float(row[1]) + 1:.9f}", "refused"),
    ):
        changed = [*lines[:2], ",".join([row[0], q1, *row[2:]]), *lines[3:]]
        assert agree(write(folder, "".join(changed))) == verdict
