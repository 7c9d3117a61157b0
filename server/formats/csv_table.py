"""A CSV file as a header plus rows that remember their line, with located field parsing."""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass

from .errors import InputError
from .files import read_text
from .limits import CSV_ROWS_MAX, NUMBER_MAX, bad_text

# Plain decimal notation only: float() would also take '1_000', 'nan' and 'infinity'.
NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_NOT_FINITE = {"nan", "inf", "infinity"}


def _names(cols: list[str], most: int = 3) -> str:
    """Column names quoted, the first few of many."""
    said = ", ".join(repr(c) for c in cols[:most])
    return said + (f" and {len(cols) - most} more" if len(cols) > most else "")


@dataclass(frozen=True)
class Row:
    """One data row: its 1-based line number in the file and its raw fields."""

    line: int
    fields: list[str]


class Table:
    """A parsed CSV file; column names match after stripping whitespace, case-insensitively."""

    def __init__(self, path, text: str):
        self.path = path
        records = self._records(text)
        if not records:
            raise InputError(path, 1, None, "empty file: expected a header row")
        self.header_line, raw = records[0]
        self.header = [h.strip() for h in raw]
        self.rows: list[Row] = []
        names = {h.lower() for h in self.header if h}
        for line, fields in records[1:]:
            self._check_repeated_header(line, fields, names)
            self._check_width(line, fields)
            self.rows.append(Row(line, fields))
        self._index: dict[str, int] = {}

    @classmethod
    def read(cls, path) -> Table:
        """Read and parse the CSV file at path."""
        return cls(path, read_text(path))

    def _records(self, text: str) -> list[tuple[int, list[str]]]:
        reader = csv.reader(io.StringIO(text, newline=""))
        records: list[tuple[int, list[str]]] = []
        start = 1
        try:
            for fields in reader:
                # Blank lines (often trailing) carry nothing; skip rather than refuse them.
                if fields and not (len(fields) == 1 and not fields[0].strip()):
                    if len(records) > CSV_ROWS_MAX:  # the header plus CSV_ROWS_MAX rows
                        raise InputError(
                            self.path,
                            start,
                            None,
                            f"more than {CSV_ROWS_MAX} data rows; split the file",
                        )
                    records.append((start, fields))
                start = reader.line_num + 1
        except csv.Error as e:
            raise InputError(self.path, reader.line_num or 1, None, f"malformed CSV: {e}") from None
        return records

    def _check_repeated_header(self, line: int, fields: list[str], names: set[str]) -> None:
        # Two files concatenated: said as such, not as the first column's "'q1' is not a number"
        # or, when the second file has other columns (a temp_c, prev_q), as "row has N fields".
        if fields[0].strip().lower() not in names and (
            len(fields) < 2 or fields[1].strip().lower() not in names
        ):
            return  # a header's first columns are among the header's (pose, q1, target...)
        if any(NUMBER.fullmatch(f.strip()) for f in fields):
            return  # a data row has numbers (joints, coordinates); a header has none
        given = [f.strip() for f in fields if f.strip()]
        known = [f for f in given if f.lower() in names]
        same = len(known) == len(given) and fields[0].strip().lower() in names
        if not (same or (len(known) >= 2 and 2 * len(known) >= len(given))):
            return
        where = f"line {line} is a second header row (the header is line {self.header_line})"
        ours = [h for h in self.header if h]
        if [f.lower() for f in given] == [h.lower() for h in ours]:
            raise InputError(self.path, line, None, f"{where}: two files concatenated? remove it")
        theirs = {f.lower() for f in given}
        diff = [
            f"{what} {_names(cols)}"
            for what, cols in (
                ("adds", [f for f in given if f.lower() not in names]),
                ("lacks", [h for h in ours if h.lower() not in theirs]),
            )
            if cols
        ]
        raise InputError(
            self.path,
            line,
            None,
            f"{where} with other columns ({', '.join(diff) or 'in another order'}): two files "
            "concatenated? give the rows below it their own file, or one header that fits all",
        )

    def _check_width(self, line: int, fields: list[str]) -> None:
        n, width = len(fields), len(self.header)
        if n != width and width == 1 and any(sep in self.header[0] for sep in ";\t"):
            # a header of one column the rows split: another separator (a spreadsheet's export
            # with decimal commas splits its rows at them), said at the header, not "row has N"
            raise InputError(
                self.path,
                self.header_line,
                None,
                f"the header is one column{self._header_hint()}"
                + (
                    "; its rows' commas look like decimal commas: give decimal points"
                    if n > 1
                    else ""
                ),
            )
        if n < width:
            raise InputError(
                self.path,
                line,
                n + 1,
                f"row has {n} fields but the header has {width}: "
                f"column '{self.header[n]}' and after are missing",
            )
        if n > width:
            raise InputError(
                self.path,
                line,
                width + 1,
                f"row has {n} fields but the header has {width} "
                f"(extra value {fields[width].strip()!r})",
            )

    def require(self, names: list[str]) -> None:
        """Locate these columns; InputError on line 1 (the header) if one is missing."""
        for name in names:
            col = self._find(name)
            if col is None:
                raise InputError(
                    self.path,
                    self.header_line,
                    None,
                    f"missing required column '{name}'{self._header_hint()}",
                )
            self._index[name] = col

    def optional(self, names: list[str]) -> list[str]:
        """Locate those of these columns that are present; return their names."""
        found = []
        for name in names:
            col = self._find(name)
            if col is not None:
                self._index[name] = col
                found.append(name)
        return found

    def require_rows(self) -> None:
        """InputError if the file has a header but no data."""
        if not self.rows:
            raise InputError(self.path, self.header_line, None, "no data rows below the header")

    def _find(self, name: str) -> int | None:
        cols = [i for i, h in enumerate(self.header) if h.lower() == name]
        if len(cols) > 1:
            raise InputError(
                self.path,
                self.header_line,
                cols[1] + 1,
                f"column '{name}' appears twice (columns {cols[0] + 1} and {cols[1] + 1})",
            )
        return cols[0] if cols else None

    def _header_hint(self) -> str:
        have = ", ".join(repr(h) for h in self.header)
        hint = f" (header: {have})"
        if len(self.header) == 1:
            for sep, what in ((";", "semicolons"), ("\t", "tabs")):
                if sep in self.header[0]:
                    hint += f"; the file seems separated by {what}, expected commas"
        return hint

    def error(self, row: Row, name: str, message: str) -> InputError:
        """An InputError at this row's field in column `name`, naming the column."""
        return InputError(self.path, row.line, self._index[name] + 1, f"column '{name}': {message}")

    def text(self, row: Row, name: str) -> str:
        """The stripped, non-empty string in column `name`, free of control characters."""
        value = row.fields[self._index[name]].strip()
        if not value:
            raise self.error(row, name, "empty field")
        why = bad_text(value)
        if why:
            raise self.error(row, name, f"the value {why}")
        return value

    def raw(self, row: Row, name: str) -> str:
        """The stripped string in column `name`, possibly empty."""
        return row.fields[self._index[name]].strip()

    def number(
        self,
        row: Row,
        name: str,
        blank: float | None = None,
        bounds: tuple[float, float] = (-NUMBER_MAX, NUMBER_MAX),
        what: str = "",
    ) -> float:
        """The finite number in column `name` within bounds (`what` says why those); an empty
        field gives `blank` if that is not None."""
        s = row.fields[self._index[name]].strip()
        if not s:
            if blank is not None:
                return blank
            raise self.error(row, name, "empty field, expected a number")
        if NUMBER.fullmatch(s):
            value = float(s)
            lo, hi = bounds
            if math.isfinite(value) and lo <= value <= hi:
                return value
            raise self.error(
                row, name, f"{s} is out of range [{lo:g}, {hi:g}]{' ' + what if what else ''}"
            )
        if s.lower().lstrip("+-") in _NOT_FINITE:
            raise self.error(row, name, f"{s!r} is not a finite number")
        raise self.error(row, name, f"{s!r} is not a number")
