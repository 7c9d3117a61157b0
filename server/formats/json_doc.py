"""A parsed JSON text that can say on which line and column each value sits."""

from __future__ import annotations

import difflib
import json
import math

import json_source_map

from .errors import InputError
from .limits import ANGLE_MAX_DEG, COORD_MAX_MM, NUMBER_MAX, bad_text


def field_name(at: tuple) -> str:
    """A readable name for a location, e.g. ('robot', 'joints', 2, 'alpha') -> robot.joints[2].alpha."""
    out = ""
    for seg in at:
        out += f"[{seg}]" if isinstance(seg, int) else (f".{seg}" if out else str(seg))
    return out or "the document"


class JsonDoc:
    """Locates values of a parsed JSON document by their path (a tuple of keys and indices)."""

    def __init__(self, path, source_map: dict | None = None):
        self.path = path
        self._map = source_map or {}

    @classmethod
    def parse(cls, path, text: str):
        """(doc, value) for this JSON text; InputError on syntax errors and duplicate keys."""
        if not text.strip():
            raise InputError(path, 1, None, "empty file: expected a JSON object")
        try:
            value = json.loads(text)
        except json.JSONDecodeError as e:
            raise InputError(path, e.lineno, e.colno, f"invalid JSON: {e.msg}") from None
        except RecursionError:
            raise InputError(path, 1, None, "invalid JSON: nested too deeply") from None
        doc = cls(path)
        doc._map = doc._source_map(text)
        return doc, value

    def _source_map(self, text: str) -> dict:
        # json.loads silently keeps the last of two equal keys, which hides typos such as a second
        # "A" meant as "B"; the ordered entry list (internal API, hence the fallback) reveals them.
        try:
            from json_source_map import handle, types

            entries = handle.value(source=text, current_location=types.Location(0, 0, 0))
        except Exception:
            return json_source_map.calculate(text)
        seen: dict = {}
        for pointer, entry in entries:
            if pointer in seen:
                key = pointer.rsplit("/", 1)[-1]
                first = seen[pointer].key_start or seen[pointer].value_start
                start = entry.key_start or entry.value_start
                raise InputError(
                    self.path,
                    start.line + 1,
                    start.column + 1,
                    f"duplicate key {key!r} (first on line {first.line + 1})",
                )
            seen[pointer] = entry
        return seen

    def where(self, at: tuple, key: bool = False) -> tuple[int | None, int | None]:
        """1-based (line, column) of the value at `at` (of its key if `key`), else of its parent."""
        for n in range(len(at), -1, -1):
            entry = self._map.get("".join(f"/{s}" for s in at[:n]))
            if entry is not None:
                loc = (
                    entry.key_start
                    if key and n == len(at) and entry.key_start
                    else entry.value_start
                )
                return loc.line + 1, loc.column + 1
        return None, None

    def error(self, at: tuple, message: str, key: bool = False) -> InputError:
        """An InputError located at `at`, whose message starts with the field's name."""
        line, column = self.where(at, key)
        return InputError(self.path, line, column, f"{field_name(at)}: {message}")

    # Typed accessors: each returns the value or raises an InputError located at `at`.

    def object(self, value, at: tuple, allowed: tuple | None = None) -> dict:
        if not isinstance(value, dict):
            raise self.error(at, f"expected an object {{...}}, got {_kind(value)}")
        if allowed is not None:
            for k in value:
                if k not in allowed:
                    hint = difflib.get_close_matches(k, allowed, n=1)
                    extra = (
                        f"; did you mean {hint[0]!r}?"
                        if hint
                        else f" (known: {', '.join(allowed)})"
                    )
                    raise self.error((*at, k), f"unknown key {k!r}{extra}", key=True)
        return value

    def require(self, obj: dict, key: str, at: tuple):
        if key not in obj:
            raise self.error(at, f"missing key {key!r}")
        return obj[key]

    def array(self, value, at: tuple, length: int | None = None) -> list:
        if not isinstance(value, list):
            raise self.error(at, f"expected an array [...], got {_kind(value)}")
        if length is not None and len(value) != length:
            raise self.error(at, f"expected {length} elements, got {len(value)}")
        return value

    def number(
        self,
        value,
        at: tuple,
        minimum: float | None = None,
        limit: float = NUMBER_MAX,
        what: str = "",
    ) -> float:
        """A finite number with |x| <= limit (`what` says why that limit, e.g. the tracker's
        range); at least `minimum` if given."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(at, f"expected a number, got {_kind(value)}")
        try:
            x = float(value)
        except OverflowError:
            x = math.inf
        if not math.isfinite(x):
            raise self.error(at, f"{value} is not a finite number")
        if not -limit <= x <= limit:
            raise self.error(
                at,
                f"{value} is out of range: |value| must be at most {limit:g}"
                f"{' ' + what if what else ''}",
            )
        if minimum is not None and x < minimum:
            raise self.error(at, f"{value} is below the minimum {minimum:g}")
        return x

    def coordinate(self, value, at: tuple) -> float:
        """A length or position in mm, within the instrument's range."""
        return self.number(value, at, limit=COORD_MAX_MM, what="mm (beyond any tracker's range)")

    def angle(self, value, at: tuple) -> float:
        """An angle in degrees, within three turns."""
        return self.number(value, at, limit=ANGLE_MAX_DEG, what="deg (three turns)")

    def integer(self, value, at: tuple, lo: int, hi: int) -> int:
        x = self.number(value, at)
        if x != int(x) or not lo <= x <= hi:
            raise self.error(at, f"{value} must be an integer in {lo}..{hi}")
        return int(x)

    def string(self, value, at: tuple) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.error(at, f"expected a non-empty string, got {_kind(value)}")
        why = bad_text(value)
        if why:
            raise self.error(at, f"the string {why}")
        return value


def _kind(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return "an array"
    return repr(value)
