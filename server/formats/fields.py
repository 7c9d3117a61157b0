"""The value types of the JSON files (bounded finite numbers, labels) and their common base."""

from __future__ import annotations

import difflib
from typing import Annotated, Any, ClassVar

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, model_validator
from pydantic.fields import FieldInfo
from pydantic_core import PydanticCustomError

from .limits import (
    ANGLE_MAX_DEG,
    COORD_MAX_MM,
    LABEL_CHARS_MAX,
    LINK_MAX_MM,
    NUMBER_MAX,
    PRINTABLE,
    bad_text,
)

# Letters like the spec's A, B, C, or short identifiers such as SMR1: they become CSV values
# and parameter names (A_x), so no spaces or punctuation.
TARGET_NAME_PATTERN = r"[A-Za-z][A-Za-z0-9_]{0,15}"


def located(message: str, *at, key: bool = False) -> PydanticCustomError:
    """A validation error placed at `at` below the validated value (at its key if `key`)."""
    return PydanticCustomError("located", "{message}", {"message": message, "at": at, "key": key})


def _bounded(limit: float, unit: str = "", minimum: float | None = None) -> FieldInfo:
    return Field(
        strict=True,  # no "12" for 12, no true for 1
        allow_inf_nan=False,
        ge=-limit if minimum is None else minimum,
        le=limit,
        json_schema_extra={"description": unit} if unit else None,
    )


# Annotated written out at each alias, so that type checkers see a float
Number = Annotated[float, _bounded(NUMBER_MAX)]
NonNegative = Annotated[float, _bounded(NUMBER_MAX, minimum=0.0)]
Coordinate = Annotated[float, _bounded(COORD_MAX_MM, "mm")]
Angle = Annotated[float, _bounded(ANGLE_MAX_DEG, "degrees")]
Link = Annotated[float, _bounded(LINK_MAX_MM, "mm")]


def _whole(value):
    # A JSON integer, or a float that is one (8080.0); never true or "8080".
    if isinstance(value, (bool, str)):
        raise PydanticCustomError("int_type", "Input should be a valid integer")
    return value


# for any type of whole-number values (an int, a Literal[1])
Whole = BeforeValidator(_whole)
Integer = Annotated[int, Whole]


def _label(text: str) -> str:
    if not text.strip():
        raise PydanticCustomError("label", "expected a non-empty string")
    why = bad_text(text)
    if why:
        raise PydanticCustomError("label", "the string {why}", {"why": why})
    return text


# The schema states _label's rule, so that what it allows the reader takes.
Label = Annotated[
    str,
    Field(
        strict=True,
        json_schema_extra={"minLength": 1, "maxLength": LABEL_CHARS_MAX, "pattern": PRINTABLE},
    ),
    AfterValidator(_label),
]
Point = Annotated[list[Coordinate], Field(min_length=3, max_length=3)]
Row4 = Annotated[list[Coordinate], Field(min_length=4, max_length=4)]
Matrix4 = Annotated[list[Row4], Field(min_length=4, max_length=4)]


class Doc(BaseModel):
    """An object of a JSON file: unknown keys refused, with the nearest known one suggested.
    Where a document lets unknown keys pass (MISSPELT_REFUSED), one that reads as a misspelt
    known key the document lacks is still refused."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    # an open document's misspelt key (cell.json's "tolerance" for tolerance_mm) would be
    # ignored without a word and its default taken: refused like a closed document's
    MISSPELT_REFUSED: ClassVar[bool] = False

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, value: Any) -> Any:
        closed = cls.model_config.get("extra") == "forbid"
        if isinstance(value, dict) and (closed or cls.MISSPELT_REFUSED):
            known = [f.alias or n for n, f in cls.model_fields.items()]
            for k in value:
                if k not in known:
                    lower = {n.lower(): n for n in known}  # MPE_um is mpe_um misspelt
                    hint = [lower[h] for h in difflib.get_close_matches(str(k).lower(), lower, 1)]
                    if closed:
                        extra = (
                            f"; did you mean {hint[0]!r}?"
                            if hint
                            else f" (known: {', '.join(known)})"
                        )
                    elif hint and hint[0] not in value:
                        extra = f"; did you mean {hint[0]!r}? (a misspelt key would be ignored)"
                    else:
                        continue
                    raise located(f"unknown key {k!r}{extra}", k, key=True)
        return value
