"""A parsed JSON text that can say on which line and column each value sits, and validate
itself against a pydantic model with errors placed there."""

from __future__ import annotations

import json

import json_source_map
from pydantic import ValidationError
from pydantic_core import ErrorDetails

from .errors import InputError

# Levels of arrays and objects a document may nest: the formats use at most five.
MAX_DEPTH = 32
NESTED_TOO_DEEPLY = f"invalid JSON: nested too deeply (more than {MAX_DEPTH} levels)"


def field_name(at: tuple) -> str:
    """A readable name for a location, e.g. ('robot', 'joints', 2, 'alpha') -> robot.joints[2].alpha."""
    out = ""
    for seg in at:
        out += f"[{seg}]" if isinstance(seg, int) else (f".{seg}" if out else str(seg))
    return out or "the document"


class JsonDoc:
    """Locates values of a parsed JSON document by their path (a tuple of keys and indices)."""

    def __init__(self, path, text: str = ""):
        self.path = path
        self._text = text
        self._map: dict | None = None  # built on the first error: it costs 5x the parse

    @classmethod
    def parse(cls, path, text: str):
        """(doc, value) for this JSON text; InputError on syntax errors and duplicate keys."""
        if not text.strip():
            raise InputError(path, 1, None, "empty file: expected a JSON object")
        doc = cls(path, text)
        try:
            try:
                value = json.loads(text, object_pairs_hook=_unique)
            except _DuplicateKey:
                json.loads(text)  # a syntax error anywhere comes first, as it would alone
                doc._source_map(text)  # raises the duplicate, located
                raise InputError(path, None, None, "a key appears twice in one object") from None
        except json.JSONDecodeError as e:
            raise InputError(path, e.lineno, e.colno, f"invalid JSON: {e.msg}") from None
        except RecursionError:
            raise InputError(path, 1, None, NESTED_TOO_DEEPLY) from None
        if _nested_deeper(value, MAX_DEPTH):
            # Below the parser's own limit, the recursive source map and validators would still
            # run out of stack on it.
            raise InputError(path, 1, None, NESTED_TOO_DEEPLY)
        return doc, value

    def _source_map(self, text: str) -> dict:
        # The ordered entry list (internal API, hence the fallback) says where a duplicate key is.
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
        if self._map is None:
            self._map = self._source_map(self._text) if self._text else {}
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

    def validate(self, model, value, context: dict | None = None):
        """`value` as an instance of the pydantic `model`; InputError at the first problem."""
        try:
            return model.model_validate(value, context=context)
        except ValidationError as e:
            at, message, key = explain(e.errors()[0])
            raise self.error(at, message, key) from None


def _nested_deeper(value, limit: int) -> bool:
    """Whether arrays and objects nest more than `limit` levels in `value` (a level at a time,
    without recursion: a tenth of the parse's time on a large document)."""
    level = [value] if isinstance(value, (dict, list)) else []
    depth = 0
    while level:
        depth += 1
        if depth > limit:
            return True
        inner = []
        for node in level:
            for child in node.values() if type(node) is dict else node:
                if type(child) is list or type(child) is dict:  # json.loads makes exactly these
                    inner.append(child)
        level = inner
    return False


class _DuplicateKey(Exception):
    pass


def _unique(pairs: list) -> dict:
    # json.loads silently keeps the last of two equal keys, which hides typos such as a second
    # "A" meant as "B".
    out = dict(pairs)
    if len(out) != len(pairs):
        raise _DuplicateKey
    return out


def explain(err: ErrorDetails) -> tuple[tuple, str, bool]:
    """(location, message, whether at the key) of one pydantic error, in this project's words."""
    at = tuple(s for s in err["loc"] if s not in UNION_TAGS)
    kind, value, ctx = err["type"], err.get("input"), err.get("ctx") or {}
    if kind == "located":
        return (*at, *ctx["at"]), ctx["message"], ctx["key"]
    if kind == "missing":
        return at[:-1], f"missing key {at[-1]!r}", False
    if kind == "extra_forbidden":
        return at, f"unknown key {at[-1]!r}", True
    if kind in EXPECTED:
        return at, f"expected {EXPECTED[kind]}, got {_kind(value)}", False
    if kind == "finite_number":
        return at, f"{value} is not a finite number", False
    if kind in ("greater_than_equal", "greater_than"):
        lo = ctx.get("ge", ctx.get("gt"))
        assert lo is not None, "pydantic's greater_than errors carry their bound"
        if lo < 0:  # the symmetric bounds of limits.py
            return at, f"{value} is out of range: |value| must be at most {-lo:g}", False
        if "gt" in ctx:
            return at, f"{value} must be above {lo:g}", False
        return at, f"{value} is below the minimum {lo:g}", False
    if kind in ("less_than_equal", "less_than"):
        hi = ctx.get("le", ctx.get("lt"))
        return at, f"{value} is out of range: it must be at most {hi:g}", False
    if kind in ("too_short", "too_long"):
        n = ctx.get("min_length") if kind == "too_short" else ctx.get("max_length")
        most = "at least" if kind == "too_short" else "at most"
        return at, f"expected {most} {n} elements, got {ctx.get('actual_length')}", False
    if kind == "literal_error":
        return at, f"expected {ctx['expected']}, got {_kind(value)}", False
    return at, err["msg"], False


# The tags of tagged unions (robot by name or inline): pydantic puts them in an error's location.
UNION_TAGS = ("built-in robot", "inline robot")
EXPECTED = {
    "float_type": "a number",
    "int_type": "an integer",
    "int_from_float": "an integer",
    "string_type": "a string",
    "bool_type": "true or false",
    "list_type": "an array [...]",
    "dict_type": "an object {...}",
    "model_type": "an object {...}",
    "model_attributes_type": "an object {...}",
}


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
