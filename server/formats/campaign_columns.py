"""meas.csv and poses.csv read a column at a time with numpy: linear in the file, tens of times
faster than a row at a time. It accepts only what the row-by-row reader would accept, with the
same numbers, and answers None for anything else (a quoted field, a stray carriage return, a bad
value anywhere): that reader then names the first bad line, or reads what it can.
"""

from __future__ import annotations

import io
import re

import numpy as np

from robocal.solver.measurements import Measurements
from robocal.solver.robot import Robot

from . import csv_table
from .cell_json import TARGET_NAME
from .csv_table import NUMBER
from .limits import LABEL_CHARS_MAX, NUMBER_MAX, SMRS_MAX

# The characters a label may not hold (Unicode Cc, Zl and Zp, as limits.bad_text says); in the
# whole file, any of them (a tab too) leaves the file to the row reader.
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")


class _Columns:
    """The header of a comma-separated text and its columns, parsed by numpy's C reader: the
    numbers in one pass, the labels in another."""

    def __init__(self, text: str):
        self.ok = False
        if "\r" in text:
            text = text.replace("\r\n", "\n")  # a lone \r is a control character, below
        if '"' in text:
            return  # quoting: csv's rules
        if text.startswith((" ", "\n")) or "\n\n" in text or "\n " in text:  # maybe blank lines
            text = "\n".join(ln for ln in text.split("\n") if ln.strip())
        if not text.endswith("\n"):
            text += "\n"
        raw = self._bytes(text)
        if raw is None:
            return  # tabs and other control characters: the row reader names them
        ends = np.flatnonzero(raw == ord("\n"))
        self.header = [h.strip().lower() for h in text[: text.index("\n")].split(",")]
        self.n = len(ends) - 1
        if len(set(self.header)) != len(self.header) or not 1 <= self.n <= csv_table.CSV_ROWS_MAX:
            return
        # every row exactly as wide as the header (numpy would take a longer row)
        commas = np.flatnonzero(raw == ord(","))
        if np.any(np.diff(np.searchsorted(commas, ends)) != len(self.header) - 1):
            return
        self.file = io.StringIO(text)
        self.ascii = text.isascii()
        if self.ascii:  # where each field of each row begins and ends, for the labels
            self.raw, self.ends = raw, ends
            self.starts = np.concatenate([[0], ends[:-1] + 1])
            self.commas = commas.reshape(len(ends), len(self.header) - 1)
        self.ok = True

    @staticmethod
    def _bytes(text: str) -> np.ndarray | None:
        """The text's bytes if it holds no control character but line breaks (no tab either)."""
        if text.isascii():
            raw = np.frombuffer(text.encode("ascii"), dtype=np.uint8)
            return None if np.any(((raw < 32) & (raw != ord("\n"))) | (raw == 127)) else raw
        if _CONTROL.search(text.replace("\n", "")):
            return None
        # a multi-byte character holds no comma or line break byte: the counts stand
        return np.frombuffer(text.encode("utf-8"), dtype=np.uint8)

    def has(self, name: str) -> bool:
        return name in self.header

    def _load(self, names: list[str], dtype):
        self.file.seek(0)
        return np.loadtxt(
            self.file,
            skiprows=1,
            delimiter=",",
            comments=None,
            usecols=[self.header.index(n) for n in names],
            dtype=dtype,
            ndmin=2,
        )

    def numbers(self, names: list[str], blank_ok=()) -> dict[str, np.ndarray] | None:
        """Each column as floats (NaN for a blank in the blank_ok ones), or None if the row reader
        would refuse a value (bounds are the caller's)."""
        strict = [n for n in names if n not in blank_ok]
        loose = [n for n in names if n in blank_ok]
        try:
            return dict(zip(names, self._load(names, float).T, strict=True))
        except ValueError:  # a blank, or no number: the row reader says which
            if not loose:
                return None
        try:
            out = dict(zip(strict, self._load(strict, float).T, strict=True)) if strict else {}
        except ValueError:
            return None
        s = np.char.strip(self._load(loose, str))
        blank = s == ""
        given = s[~blank]
        if not all(NUMBER.fullmatch(x) for x in given.tolist()):
            return None
        v = np.full(s.shape, np.nan)
        v[~blank] = given.astype(float)
        out.update(zip(loose, v.T, strict=True))
        return out

    def labels(self, names: list[str]) -> dict[str, np.ndarray] | None:
        """The stripped labels, or None if one is blank or too long (control characters were
        refused for the whole file). An ASCII file's come straight from its bytes."""
        out: dict[str, np.ndarray] = {}
        if self.ascii:
            for n in names:
                field = self._field_bytes(self.header.index(n))
                if field is None:
                    return None
                out[n] = field
        else:
            loaded = np.char.strip(self._load(names, str))
            out.update(zip(names, loaded.T, strict=True))
        for v in out.values():
            lengths = np.char.str_len(v)
            if np.any(lengths == 0) or np.any(lengths > LABEL_CHARS_MAX):
                return None
        return out

    def _field_bytes(self, j: int) -> np.ndarray | None:
        """Field j of every data row, stripped of spaces, as fixed-width bytes (numpy 'S'); None
        for a field wider than a label may be (the row reader judges it)."""
        left = self.starts[1:] if j == 0 else self.commas[1:, j - 1] + 1
        right = self.ends[1:] if j == self.commas.shape[1] else self.commas[1:, j]
        width = int(max(1, (right - left).max()))
        if width > LABEL_CHARS_MAX:
            return None
        at = np.minimum(left[:, None] + np.arange(width), len(self.raw) - 1)
        cells = np.where(at < right[:, None], self.raw[at], ord(" ")).astype(np.uint8)
        return np.strings.strip(cells.view(f"S{width}").ravel())


def _text(label) -> str:
    """A label as text (an ASCII file's labels are bytes)."""
    return label.decode("ascii") if isinstance(label, bytes) else label


def _within(v: np.ndarray, lo: float, hi: float) -> bool:
    """Finite and within bounds, blanks (NaN) aside: the caller decides where blanks may be."""
    given = ~np.isnan(v)
    return bool(np.all(np.isfinite(v[given]) & (v[given] >= lo) & (v[given] <= hi)))


def _joints(cols: dict, robot: Robot, tol_deg: float):
    """(N, n) degrees within the joint limits, or None."""
    q = np.column_stack([cols[f"q{i + 1}"] for i in range(robot.n_joints)])
    lo, hi = np.rad2deg(robot.lower), np.rad2deg(robot.upper)
    if not _within(q, -NUMBER_MAX, NUMBER_MAX) or np.any(np.isnan(q)):
        return None
    return None if np.any(q < lo - tol_deg) or np.any(q > hi + tol_deg) else q


def _poses(ids: np.ndarray, q_deg: np.ndarray, same_tol_deg: float):
    """Pose ids in order of first appearance, each row's pose, the first row of each; None if a
    pose's rows disagree on a joint."""
    # a pose's rows are usually together: look the ids up once per run of equal ids
    starts = np.flatnonzero(np.concatenate([[True], ids[1:] != ids[:-1]]))
    index: dict = {}
    run_pose = [index.setdefault(p, len(index)) for p in ids[starts].tolist()]
    inv = np.repeat(np.array(run_pose, dtype=np.intp), np.diff(np.append(starts, len(ids))))
    first = np.full(len(index), len(ids), dtype=np.intp)
    np.minimum.at(first, inv, np.arange(len(ids)))
    if np.any(np.abs(q_deg - q_deg[first[inv]]) > same_tol_deg):
        return None
    return [_text(p) for p in index], inv, first


def read_campaign_columns(
    text: str, robot: Robot, measured, extras, bounds, limit_tol: float, same_tol: float
) -> Measurements | None:
    """A meas.csv's campaign, or None where the row reader must decide."""
    t = _Columns(text)
    joints = [f"q{i}" for i in range(1, robot.n_joints + 1)]
    if not t.ok or not all(t.has(c) for c in ["pose", *joints, "target", *measured]):
        return None
    if any(t.has(f"prev_{c}") for c in joints):  # the row reader checks and reads them
        return None
    present = [c for c in extras if t.has(c)]
    cols = t.numbers([*joints, *measured, *present], blank_ok=present)
    labels = t.labels(["pose", "target"])
    if cols is None or labels is None:
        return None
    points = np.column_stack([cols[c] for c in measured])
    q = _joints(cols, robot, limit_tol)
    if q is None or np.any(np.isnan(points)):
        return None
    if not all(_within(cols[c], *bounds[c][0]) for c in [*measured, *present]):
        return None
    names = np.array(sorted(set(labels["target"].tolist())))
    if len(names) > SMRS_MAX:  # the row reader names the line
        return None
    found = [_text(n) for n in names.tolist()]
    if not all(TARGET_NAME.fullmatch(n) for n in found):
        return None
    k = np.searchsorted(names, labels["target"])
    poses = _poses(labels["pose"], q, same_tol)
    if poses is None:
        return None
    pose_ids, inv, first = poses
    m, K = len(pose_ids), len(names)
    if np.bincount(inv * K + k, minlength=m * K).max() > 1:  # a (pose, target) twice
        return None
    xyz = np.full((m, K, 3), np.nan)
    xyz[inv, k] = points
    extra = {}
    for c in present:
        extra[c] = np.full((m, K), np.nan)
        extra[c][inv, k] = cols[c]
    return Measurements(
        pose_ids,
        np.deg2rad(q[first]),
        tuple(found),
        xyz,
        extra.get("time_s"),
        extra.get("temp_c"),
    )


def read_poses_columns(text: str, robot: Robot, extras, bounds, limit_tol: float, same_tol: float):
    """A poses.csv (or meas.csv): (ids, q rad, time_s, temp_c), or None where the row reader
    must decide."""
    t = _Columns(text)
    joints = [f"q{i}" for i in range(1, robot.n_joints + 1)]
    if not t.ok or not all(t.has(c) for c in ["pose", *joints]):
        return None
    if any(t.has(f"prev_{c}") for c in joints):  # the row reader checks and reads them
        return None
    present = [c for c in extras if t.has(c)]
    cols = t.numbers([*joints, *present], blank_ok=present)
    labels = t.labels(["pose"])
    if cols is None or labels is None:
        return None
    q = _joints(cols, robot, limit_tol)
    poses = None if q is None else _poses(labels["pose"], q, same_tol)
    if q is None or poses is None:
        return None
    pose_ids, _, first = poses
    if not t.has("target") and len(pose_ids) != t.n:  # a pose twice, one row each expected
        return None
    values = {}
    for c in present:
        # the row reader reads these on each pose's first row only
        values[c] = cols[c][first]
        if not _within(values[c], *bounds[c][0]):
            return None
    return pose_ids, np.deg2rad(q[first]), values.get("time_s"), values.get("temp_c"), None
