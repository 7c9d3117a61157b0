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
_PRINTABLE = bytes([ord("\n"), *range(32, 127)])  # an ASCII text's bytes but control characters


class _Columns:
    """The header of a comma-separated text and its columns, parsed by numpy's C reader: the
    numbers in one pass, the labels in another."""

    def __init__(self, text: str):
        self.ok = False
        if "\r" in text:
            text = text.replace("\r\n", "\n")  # a lone \r is a control character, below
        if '"' in text:
            return  # quoting: csv's rules
        if not text.endswith("\n"):
            text += "\n"
        # a blank line is a row without commas: only a file refused as it is may have one
        if not self._parse(text) and (
            text.startswith((" ", "\n")) or "\n\n" in text or "\n " in text
        ):
            self._parse("\n".join(ln for ln in text.split("\n") if ln.strip()) + "\n")

    def _parse(self, text: str) -> bool:
        """Take the text if it has no control character but line breaks and every row is as
        wide as the header; whether it did."""
        raw = self._bytes(text)
        if raw is None:
            return False  # tabs and other control characters: the row reader names them
        self.header = [h.strip().lower() for h in text[: text.index("\n")].split(",")]
        width = len(self.header)
        # every comma and line end in order: a row exactly as wide as the header holds width - 1
        # commas and then its end (numpy's reader would take a longer row)
        sep = _positions(raw[:-_PAD], (ord(","), ord("\n")))
        if len(set(self.header)) != width or len(sep) % width:
            return False
        sep = sep.reshape(-1, width)
        self.n = len(sep) - 1
        if not 1 <= self.n <= csv_table.CSV_ROWS_MAX:
            return False
        if np.any(raw[sep[:, :-1]] != ord(",")) or np.any(raw[sep[:, -1]] != ord("\n")):
            return False
        self.text = text
        self.ascii = text.isascii()
        self.raw, self.sep, self.ends, self.commas = raw, sep, sep[:, -1], sep[:, :-1]
        self.starts = np.concatenate([[0], self.ends[:-1] + 1])
        self.view = np.lib.stride_tricks.sliding_window_view(raw, _PAD)
        # a 64-bit little-endian word at every byte offset (unaligned reads)
        self.words = np.ndarray((len(raw) - 7,), dtype="<u8", buffer=raw, strides=(1,))
        self.ok = True
        return True

    @staticmethod
    def _bytes(text: str) -> np.ndarray | None:
        """The text's bytes and _PAD spaces (so a fixed-width window fits past any field) if it
        holds no control character but line breaks (no tab either)."""
        if text.isascii():
            data = text.encode("ascii")
            if data.translate(None, _PRINTABLE):  # what is left is control characters
                return None
            return np.frombuffer(data + b" " * _PAD, dtype=np.uint8)
        if _CONTROL.search(text.replace("\n", "")):
            return None
        # a multi-byte character holds no comma or line break byte: the counts stand
        return np.frombuffer((text + " " * _PAD).encode("utf-8"), dtype=np.uint8)

    def has(self, name: str) -> bool:
        return name in self.header

    def _load(self, names: list[str], dtype):
        return np.loadtxt(
            io.StringIO(self.text),
            skiprows=1,
            delimiter=",",
            comments=None,
            usecols=[self.header.index(n) for n in names],
            dtype=dtype,
            ndmin=2,
        )

    def numbers(self, names: list[str], blank_ok=(), rows=None) -> dict[str, np.ndarray] | None:
        """Each column as floats (NaN for a blank in the blank_ok ones), or None if the row reader
        would refuse a value (bounds are the caller's). Plain decimals of an ASCII file straight
        from its bytes; numpy's loadtxt if any field holds something else. rows: only those data
        rows, and None unless their fields are plain decimals with points lined up."""
        cols = [self.header.index(n) for n in names]
        if rows is not None:
            v = self._decimals(cols, rows, horner=False) if self.ascii else None
            if v is None:
                return None
        else:
            v = self._decimals(cols) if self.ascii else None
        if v is None:
            return self._numbers_loaded(names, blank_ok)
        strict = [i for i, n in enumerate(names) if n not in blank_ok]
        if np.isnan(v[:, strict]).any():
            return None  # a blank: the row reader says where
        return dict(zip(names, v.T, strict=True))

    def _decimals(self, cols: list[int], rows=None, horner=True) -> np.ndarray | None:
        """Fields cols of every data row (rows, len(cols)) as floats (NaN where blank) if each is
        a plain decimal of at most MAX_DIGITS digits; None otherwise (a space, an exponent, a
        longer number...). Eight bytes at a time where each column's points line up (a written
        file's), else by Horner's rule; all columns of a block of rows at once, so the block's
        bytes stay in cache. rows: those data rows only (and Horner's rule not tried)."""
        c = np.asarray(cols)
        sep = self.sep[1:] if rows is None else self.sep[1:][rows]
        right = sep[:, c]
        left = sep[:, np.maximum(c - 1, 0)] + 1  # past the comma before
        starts = self.starts[1:] if rows is None else self.starts[1:][rows]
        left[:, c == 0] = starts[:, None]  # the first field: past the line before
        # the first field given in each column says where its point is (from its end)
        length = right - left
        k = np.argmax(length > 0, axis=0)
        found = [self.text[left[i, j] : right[i, j]].find(".") for j, i in enumerate(k)]
        point = np.array(
            [f if f < 0 else int(length[i, j]) - f for j, (i, f) in enumerate(zip(k, found))]
        )
        out = np.empty((len(right), len(cols)))
        step = max(1, _FIELDS // len(cols))
        for lo in range(0, len(right), step):
            v = _words(self.words, left[lo : lo + step], right[lo : lo + step], point)
            if v is None:
                return self._horner(cols) if horner and rows is None else None
            out[lo : lo + step] = v
        return out

    def repeats(self, cols: list[int], ref: np.ndarray) -> bool:
        """Whether fields cols (adjacent, in order) of every data row are byte for byte those of
        data row ref[row]: eight bytes at a time over the span from the first to the last."""
        if list(cols) != list(range(cols[0], cols[0] + len(cols))) or not self.ascii:
            return False
        left, _ = self._bounds(cols[0])
        _, right = self._bounds(cols[-1])
        span = right - left
        other = np.flatnonzero(ref != np.arange(len(ref)))  # a pose's later rows
        if not len(other):
            return True
        a, b, n = left[other], left[ref[other]], span[other]
        if np.any(n != span[ref[other]]) or n.min() < 8 or n.max() > _SPAN_MAX:
            return False
        for lo in range(0, len(other), _ROWS_AT_ONCE):  # rows near each other: in cache
            a1, b1, n1 = (v[lo : lo + _ROWS_AT_ONCE] for v in (a, b, n))
            for k in range(0, int(n1.max()), 8):
                off = np.minimum(k, n1 - 8)  # the last word ends at the span's end
                if np.any(self.words[a1 + off] != self.words[b1 + off]):
                    return False
        return True

    def _horner(self, cols: list[int]) -> np.ndarray | None:
        """_decimals by Horner's rule over each field's bytes, for any layout of points."""
        c = np.asarray(cols)
        out = np.empty((self.n, len(cols)))
        step = max(1, _FIELDS // len(cols))
        for lo in range(0, self.n, step):
            sep = self.sep[lo : lo + step + 1]  # the line before, then the chunk's
            left = sep[1:, c - 1] + 1  # past the comma before; the first field, past the line
            left[:, c == 0] = sep[:-1, -1:] + 1
            length = sep[1:, c] - left
            if length.max() > MAX_FIELD:
                return None
            v = _parse_decimals(self._window(left.ravel(), int(length.max())), length.ravel())
            if v is None:
                return None
            out[lo : lo + step] = v.reshape(-1, len(cols))
        return out

    def _bounds(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Where field j of each data row begins and ends (byte offsets)."""
        left = self.starts[1:] if j == 0 else self.commas[1:, j - 1] + 1
        right = self.ends[1:] if j == self.commas.shape[1] else self.commas[1:, j]
        return left, right

    def _window(self, left: np.ndarray, width: int) -> np.ndarray:
        """(width, rows) bytes from each offset: a field and what follows it."""
        return np.ascontiguousarray(self.view[left, : max(width, 1)].T)

    def _numbers_loaded(self, names: list[str], blank_ok=()) -> dict[str, np.ndarray] | None:
        """numbers() by numpy's loadtxt."""
        strict = [n for n in names if n not in blank_ok]
        loose = [n for n in names if n in blank_ok]
        try:
            v = self._load(names, float)
            # numpy reads 'NaN' and 'inf' as numbers: the row reader refuses them, by name
            return dict(zip(names, v.T, strict=True)) if np.isfinite(v).all() else None
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
        left, right = self._bounds(j)
        width = int(max(1, (right - left).max()))
        if width > LABEL_CHARS_MAX:
            return None
        cells = self._window(left, width).T.copy()
        cells[np.arange(width) >= (right - left)[:, None]] = ord(" ")
        return np.strings.strip(cells.view(f"S{width}").ravel())


# Digits a decimal may have for its value to be the exact quotient of two doubles (its digits as
# an integer below 2^53, a power of ten below 10^22): the one rounding of that division is the
# correctly rounded decimal, as float() gives (Clinger's fast path).
MAX_DIGITS = 15
MAX_FIELD = 24  # bytes: a sign, a point, 15 digits and leading zeros
_POW10 = 10.0 ** np.arange(MAX_FIELD + 1)
_ROWS_AT_ONCE = 4096
_SPAN_MAX = 512  # bytes of fields compared as a whole
_FIELDS = 1 << 15  # fields parsed at once: a window of them stays in cache
_PAD = LABEL_CHARS_MAX + MAX_FIELD  # spaces after the text: no field's window runs off its end
_ZEROS = int.from_bytes(b"0" * 8, "little")
_POW10_INT = np.array([10**k for k in range(17)], dtype=np.uint64)
_LOW_BYTES = np.array([(1 << (8 * k)) - 1 for k in range(9)], dtype=np.uint64)  # k bytes set


def _not_digits(word: np.ndarray) -> bool:
    """Whether any byte of the words (ASCII: all below 0x80) is not a digit: past '9' the byte
    plus 0x46 sets its top bit; below '0' the byte with its top bit set, less 0x30, clears it."""
    top = np.uint64(0x8080808080808080)
    high = (word + np.uint64(0x4646464646464646)) | ~((word | top) - np.uint64(_ZEROS))
    return bool((high & top).any())


def _swar8(word: np.ndarray) -> np.ndarray:
    """Eight ASCII digits a word (the first in its lowest byte) as their integer: pairs, then
    fours, then all eight, each step one multiplication and shift (wrapping arithmetic)."""
    v = word - np.uint64(_ZEROS)
    v = (v * np.uint64(10) + (v >> np.uint64(8))) & np.uint64(0x00FF00FF00FF00FF)
    v = (v * np.uint64(100) + (v >> np.uint64(16))) & np.uint64(0x0000FFFF0000FFFF)
    return (v * np.uint64(10000) + (v >> np.uint64(32))) & np.uint64(0xFFFFFFFF)


def _positions(raw: np.ndarray, chars: tuple[int, ...], chunk: int = 1 << 22) -> np.ndarray:
    """Offsets of the bytes equal to any of chars, a chunk at a time (no file-sized masks), as
    32-bit integers when the text's size allows (a file is at most FILE_BYTES_MAX)."""
    kind = np.int32 if len(raw) < 2**31 else np.intp
    out = []
    for lo in range(0, len(raw), chunk):
        part = raw[lo : lo + chunk]
        hit = part == chars[0]
        for c in chars[1:]:
            hit |= part == c
        out.append((np.flatnonzero(hit) + lo).astype(kind))
    return np.concatenate(out) if out else np.zeros(0, dtype=kind)


def _words(words: np.ndarray, left: np.ndarray, right: np.ndarray, point: np.ndarray):
    """Fields [left, right) (rows, columns) as floats (NaN where empty) if each is
    [+-]digits[.digits] of 1 to MAX_DIGITS digits within 16 bytes, its point `point` bytes from
    its end (point[j] for column j, -1: none); None otherwise (Horner's rule then decides).

    words holds a little-endian 64-bit word at every byte offset. Each field's last 16 bytes as
    two words: the bytes before the field, its sign and its point made '0', every byte must be
    a digit, and eight digits become their integer in three multiplications (SWAR); the point
    taken out of that integer, one division by a power of ten gives the value, exactly as
    float() rounds it (Clinger's fast path, as in _parse_decimals)."""
    length = right - left
    given = length > 0
    if length.max() > 16 or int(right.min()) < 16:
        return None
    hi = words[right - 16]  # bytes 0-7 of the 16 (byte 0 the word's lowest)
    lo = words[right - 8]  # bytes 8-15
    outside = (16 - length).astype(np.uint64)  # bytes before the field
    has = point >= 0
    q = np.where(has, 16 - point, 0)  # the point's byte of the 16
    shift = (8 * (q % 8)).astype(np.uint64)
    at = (np.where(q < 8, hi, lo) >> shift) & np.uint64(0xFF)
    if np.any(has & given & ((at != ord(".")) | (outside > q))):
        return None  # points not lined up: Horner's rule
    for word, mine in ((hi, has & (q < 8)), (lo, has & (q >= 8))):
        mask = np.where(mine, np.uint64(0xFF) << shift, np.uint64(0))
        word &= ~mask
        word |= np.uint64(_ZEROS) & mask
    sign = np.where(outside < 8, hi, lo) >> (np.uint64(8) * (outside % np.uint64(8)))
    sign &= np.uint64(0xFF)
    minus = sign == ord("-")
    signed = given & (minus | (sign == ord("+")))
    outside += signed  # a sign counts as a leading zero
    for word, skip in ((hi, outside), (lo, np.maximum(outside, 8) - 8)):
        mask = _LOW_BYTES[np.minimum(skip, 8)]
        word &= ~mask
        word |= np.uint64(_ZEROS) & mask
    digits = length - signed - has
    if np.any(given & ((digits < 1) | (digits > MAX_DIGITS))):
        return None
    if _not_digits(hi) or _not_digits(lo):
        return None
    x = _swar8(hi) * np.uint64(10**8) + _swar8(lo)
    frac = np.where(has, point - 1, 0)  # digits after the point
    f = _POW10_INT[frac]
    r = x % f
    x = np.where(has, (x - r) // np.uint64(10) + r, x)  # the point was a 0 in x: out with it
    v = x.astype(np.float64) / _POW10[frac]
    v[minus] *= -1  # -0 too, as float("-0.0")
    v[~given] = np.nan
    return v


_END = ord(",")  # written past each field's end: no field holds one


def _parse_decimals(window: np.ndarray, length: np.ndarray) -> np.ndarray | None:
    """Fields as floats, NaN where empty: window (width, rows) holds each field's bytes from its
    start, length (rows,) its length. None unless each is [+-]digits[.digits] (or .digits) of at
    most MAX_DIGITS digits: NUMBER's plain decimals, whose float() this equals to the bit.

    Byte arithmetic over the whole window, then Horner's rule a position at a time over all
    fields: a digit multiplies by ten and adds itself, any other byte leaves the number."""
    window[np.arange(len(window))[:, None] >= length] = _END
    d = window - np.uint8(ord("0"))  # wraps past 9 for anything but a digit
    digit = d <= 9
    point = window == ord(".")
    other = ~(digit | point | (window == _END))
    other[0] &= (window[0] != ord("-")) & (window[0] != ord("+"))
    if other.any():
        return None
    given = length > 0
    digits = digit.sum(axis=0)
    if np.any(point.sum(axis=0) > 1) or np.any(given & (digits == 0)) or digits.max() > MAX_DIGITS:
        return None
    times = (1 + 9 * digit).astype(np.uint8)
    d *= digit
    acc = np.zeros(window.shape[1], dtype=np.int64)
    frac = np.zeros(window.shape[1], dtype=np.int64)
    seen = np.zeros(window.shape[1], dtype=bool)  # a point so far
    for j in range(len(window)):
        acc *= times[j]
        acc += d[j]
        seen |= point[j]
        frac += digit[j] & seen
    v = acc / _POW10[frac]
    v = np.where(window[0] == ord("-"), -v, v)
    v[~given] = np.nan
    return v


def _text(label) -> str:
    """A label as text (an ASCII file's labels are bytes)."""
    return label.decode("ascii") if isinstance(label, bytes) else label


def _within(v: np.ndarray, lo: float, hi: float) -> bool:
    """Finite and within bounds, blanks (NaN) aside: the caller decides where blanks may be."""
    least, most = v.min(initial=lo), v.max(initial=hi)  # NaN if any is blank
    if not (np.isnan(least) or np.isnan(most)):
        return bool(lo <= least and most <= hi and np.isfinite(least) and np.isfinite(most))
    given = ~np.isnan(v)
    return bool(np.all(np.isfinite(v[given]) & (v[given] >= lo) & (v[given] <= hi)))


def _joints(cols: dict, robot: Robot, tol_deg: float):
    """(N, n) degrees within the joint limits, or None."""
    q = np.column_stack([cols[f"q{i + 1}"] for i in range(robot.n_joints)])
    lo, hi = np.rad2deg(robot.lower), np.rad2deg(robot.upper)
    if not _within(q, -NUMBER_MAX, NUMBER_MAX) or np.any(np.isnan(q)):
        return None
    return None if np.any(q < lo - tol_deg) or np.any(q > hi + tol_deg) else q


def _groups(ids: np.ndarray):
    """Pose ids in order of first appearance, each row's pose, the first row of each."""
    # a pose's rows are usually together: look the ids up once per run of equal ids; numbered
    # in order of first appearance
    starts = np.flatnonzero(np.concatenate([[True], ids[1:] != ids[:-1]]))
    names, seen, run_name = np.unique(ids[starts], return_index=True, return_inverse=True)
    order = np.argsort(seen, kind="stable")
    number = np.empty(len(order), dtype=np.intp)
    number[order] = np.arange(len(order))
    names = names[order]
    index = (names.astype("U") if names.dtype.kind == "S" else names).tolist()  # as text
    inv = np.repeat(number[run_name.ravel()], np.diff(np.append(starts, len(ids))))
    first = starts[seen[order]]  # a pose's first row begins its first run
    return index, inv, first


def first_given(values: np.ndarray, inv: np.ndarray, first: np.ndarray) -> np.ndarray:
    """Per pose, its first row's value that is given (not blank: a reading's temperature may
    be missing where the pose's other SMRs have it), NaN where none is."""
    rows = np.full(len(first), len(values))
    given = np.flatnonzero(~np.isnan(values))  # a blank is NaN; an infinity is refused later
    np.minimum.at(rows, inv[given], given)
    return np.where(rows < len(values), values[np.minimum(rows, len(values) - 1)], np.nan)


def _poses(ids: np.ndarray, q_deg: np.ndarray, same_tol_deg: float):
    """_groups, or None if a pose's rows disagree on a joint."""
    index, inv, first = _groups(ids)
    if np.any(np.abs(q_deg - q_deg[first[inv]]) > same_tol_deg):
        return None
    return index, inv, first


def _read_numbers(
    t: _Columns, robot: Robot, joints, others, blank_ok, first, inv, limit_tol, same_tol
):
    """Each pose's joints (m, n) degrees and the other columns per row, or None. A pose's rows
    usually repeat its joints byte for byte: then they are read on its first row only."""
    if t.repeats([t.header.index(c) for c in joints], first[inv]):
        at_first = t.numbers(joints, rows=first)
        cols = None if at_first is None else t.numbers(others, blank_ok=blank_ok)
        q = None if at_first is None or cols is None else _joints(at_first, robot, limit_tol)
        if q is not None and cols is not None:
            return q, cols
    cols = t.numbers([*joints, *others], blank_ok=blank_ok)
    q = None if cols is None else _joints(cols, robot, limit_tol)
    if q is None or cols is None or np.any(np.abs(q - q[first[inv]]) > same_tol):
        return None  # a pose's rows disagree on a joint: the row reader says where
    return q[first], cols


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
    labels = t.labels(["pose", "target"])
    if labels is None:
        return None
    pose_ids, inv, first = _groups(labels["pose"])
    read = _read_numbers(
        t, robot, joints, [*measured, *present], present, first, inv, limit_tol, same_tol
    )
    if read is None:
        return None
    q, cols = read
    points = np.column_stack([cols[c] for c in measured])
    if np.any(np.isnan(points)):
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
        np.deg2rad(q),
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
    pose_ids, inv, first = poses
    if not t.has("target") and len(pose_ids) != t.n:  # a pose twice, one row each expected
        return None
    values = {}
    for c in present:
        values[c] = first_given(cols[c], inv, first)
        if not _within(values[c], *bounds[c][0]):
            return None
    return pose_ids, np.deg2rad(q[first]), values.get("time_s"), values.get("temp_c"), None
