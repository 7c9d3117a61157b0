"""The tracker line protocol (see PROTOCOL.md): pure encoders and parsers, no I/O."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from ..line_errors import ProtocolError

MAX_ID = 999_999_999
MAX_SAMPLES = 100_000
MAX_SEARCH_RADIUS_MM = 200.0
NOMINAL_SAMPLE_RATE_HZ = 1000.0  # what clients assume when they budget a MEASURE's duration
SEARCH_SETUP_S = 0.2
SEARCH_AREA_MM2_S = 1000.0  # the spiral sweeps this much area per second

COMMANDS: dict[str, tuple[type, ...]] = {
    "ID": (),
    "POINT": (float, float, float),
    "SEARCH": (float,),
    "MEASURE": (int,),
    "STABLE": (int, float),
    "WEATHER": (),
    "STATUS": (),
}
# Repeating these changes nothing a second time (MEASURE only costs time); SEARCH may relock.
IDEMPOTENT = frozenset({"ID", "POINT", "MEASURE", "STABLE", "WEATHER", "STATUS"})
MAX_STABLE_WAIT_S = 60.0
MEASURE_OK, MEASURE_INACCURATE = "OK", "INACCURATE"

_ID = re.compile(r"#(\d{1,9})")
_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?")
_INT = re.compile(r"\d{1,9}")  # every count fits; int() refuses over 4300 digits
_TOKEN = re.compile(r"[!-~]+")  # printable ASCII without spaces
_CODE = re.compile(r"[A-Z][A-Z_]*")


class ErrorCode(StrEnum):
    """Device error codes carried by `ERR` replies."""

    TARGET_NOT_FOUND = "TARGET_NOT_FOUND"
    BEAM_BROKEN = "BEAM_BROKEN"
    INACCURATE = "INACCURATE"
    BAD_REQUEST = "BAD_REQUEST"
    BUSY = "BUSY"


class TrackerError(Exception):
    """The device answered with an error code."""

    def __init__(self, code: str, message: str = ""):
        super().__init__(f"{code}: {message}" if message else str(code))
        self.code, self.message = str(code), message


@dataclass(frozen=True)
class Request:
    """A parsed request line."""

    id: int
    command: str
    args: tuple = ()


@dataclass(frozen=True)
class ReplyLine:
    """A reply line split into id, OK/ERR and its fields, not yet interpreted."""

    id: int
    ok: bool
    fields: tuple[str, ...]


@dataclass(frozen=True)
class Ident:
    """Who the tracker is."""

    model: str
    serial: str
    firmware: str


@dataclass(frozen=True, eq=False)
class Measurement:
    """A stationary measurement: mean SMR centre and per-axis sample spread (mm)."""

    mean_mm: np.ndarray  # (3,)
    std_mm: np.ndarray  # (3,)
    samples: int
    status: str  # MEASURE_OK or MEASURE_INACCURATE

    @property
    def ok(self) -> bool:
        return self.status == MEASURE_OK


@dataclass(frozen=True)
class Weather:
    """The tracker's weather station."""

    temp_c: float
    pressure_hpa: float
    humidity_pct: float


@dataclass(frozen=True, eq=False)
class Status:
    """Whether the beam is locked on a target, and where it points (mm)."""

    locked: bool
    aim_mm: np.ndarray  # (3,)


def search_time_s(radius_mm: float) -> float:
    """Seconds a spiral search takes to sweep out to radius_mm."""
    return SEARCH_SETUP_S + math.pi * radius_mm**2 / SEARCH_AREA_MM2_S


def _num(x: float) -> str:
    return f"{float(x):.6f}"


def _body(line: str) -> str:
    """The line without its terminator; rejects partial and non-ASCII lines."""
    if not line.endswith("\n"):
        raise ProtocolError(f"partial line (no newline): {line[:60]!r}")
    body = line[:-1].removesuffix("\r")
    if any(not (32 <= ord(c) < 127) for c in body):
        raise ProtocolError(f"not printable ASCII: {body[:60]!r}")
    return body


def _split_id(body: str) -> tuple[int, list[str]]:
    tokens = body.split()
    m = _ID.fullmatch(tokens[0]) if tokens else None
    if not m:
        raise ProtocolError(f"missing request id '#<n>': {body[:60]!r}")
    return int(m.group(1)), tokens[1:]


def parse_float(token: str, what: str = "value", req_id: int | None = None) -> float:
    """A finite decimal number; rejects nan, inf, hex and anything float() would stretch to."""
    if not _NUMBER.fullmatch(token):
        raise ProtocolError(f"{what}: not a number: {token!r}", req_id)
    x = float(token)
    if not math.isfinite(x):
        raise ProtocolError(f"{what}: not finite: {token!r}", req_id)
    return x


def parse_int(token: str, what: str = "value", req_id: int | None = None) -> int:
    if not _INT.fullmatch(token):
        raise ProtocolError(f"{what}: not an integer 0..999999999: {token!r}", req_id)
    return int(token)


def encode_request(req_id: int, command: str, *args) -> str:
    """`#<id> COMMAND args...\\n`; floats to 1 nm, ints as they are."""
    if not 0 < req_id <= MAX_ID:
        raise ValueError(f"request id must be 1..{MAX_ID}, got {req_id}")
    kinds = COMMANDS.get(command)
    if kinds is None:
        raise ValueError(f"unknown command {command!r}")
    if len(args) != len(kinds):
        raise ValueError(f"{command} takes {len(kinds)} arguments, got {len(args)}")
    parts = [f"#{req_id}", command]
    for kind, a in zip(kinds, args):
        if kind is int:
            parts.append(str(int(a)))
        elif not math.isfinite(float(a)):
            raise ValueError(f"{command}: argument not finite: {a!r}")
        else:
            parts.append(_num(a))
    return " ".join(parts) + "\n"


def parse_request(line: str) -> Request:
    """Parse and validate a request line; ProtocolError (with req_id if readable) otherwise."""
    req_id, tokens = _split_id(_body(line))
    if not tokens:
        raise ProtocolError("missing command", req_id)
    command, raw = tokens[0], tokens[1:]
    kinds = COMMANDS.get(command)
    if kinds is None:
        raise ProtocolError(f"unknown command {command!r}", req_id)
    if len(raw) != len(kinds):
        raise ProtocolError(f"{command} takes {len(kinds)} arguments, got {len(raw)}", req_id)
    args = tuple(
        parse_int(t, command, req_id) if k is int else parse_float(t, command, req_id)
        for k, t in zip(kinds, raw)
    )
    if command == "SEARCH" and not 0 < args[0] <= MAX_SEARCH_RADIUS_MM:
        raise ProtocolError(f"SEARCH radius must be in (0, {MAX_SEARCH_RADIUS_MM}] mm", req_id)
    if command == "MEASURE" and not 1 <= args[0] <= MAX_SAMPLES:
        raise ProtocolError(f"MEASURE samples must be 1..{MAX_SAMPLES}", req_id)
    if command == "STABLE" and not (
        1 <= args[0] <= MAX_SAMPLES and 0 <= args[1] <= MAX_STABLE_WAIT_S
    ):
        raise ProtocolError(
            f"STABLE samples must be 1..{MAX_SAMPLES} and wait 0..{MAX_STABLE_WAIT_S:g} s", req_id
        )
    return Request(req_id, command, args)


def encode_reply(req_id: int, value) -> str:
    """The reply line for a result: Ident, bool (locked), Measurement, Weather, Status or error."""
    if isinstance(value, TrackerError):
        message = "".join(c if 32 <= ord(c) < 127 else "?" for c in value.message)
        return f"#{req_id} ERR {value.code} {message}".rstrip() + "\n"
    if isinstance(value, Ident):
        fields = [value.model, value.serial, value.firmware]
        if not all(_TOKEN.fullmatch(f) for f in fields):
            raise ValueError(f"ident fields must be single printable tokens: {fields}")
    elif isinstance(value, bool):
        fields = ["LOCKED" if value else "UNLOCKED"]
    elif isinstance(value, Measurement):
        fields = [
            *map(_num, value.mean_mm),
            *map(_num, value.std_mm),
            str(value.samples),
            value.status,
        ]
    elif isinstance(value, Weather):
        fields = [_num(value.temp_c), _num(value.pressure_hpa), _num(value.humidity_pct)]
    elif isinstance(value, Status):
        fields = ["LOCKED" if value.locked else "UNLOCKED", *map(_num, value.aim_mm)]
    else:
        raise TypeError(f"no reply encoding for {type(value).__name__}")
    return f"#{req_id} OK " + " ".join(fields) + "\n"


def split_reply(line: str) -> ReplyLine:
    """`#<id> OK fields...` or `#<id> ERR CODE message`; ProtocolError for anything else."""
    req_id, tokens = _split_id(_body(line))
    if not tokens or tokens[0] not in ("OK", "ERR"):
        raise ProtocolError(f"reply must say OK or ERR after the id: {line[:60]!r}", req_id)
    return ReplyLine(req_id, tokens[0] == "OK", tuple(tokens[1:]))


def _locked(token: str, req_id: int) -> bool:
    if token not in ("LOCKED", "UNLOCKED"):
        raise ProtocolError(f"expected LOCKED or UNLOCKED, got {token!r}", req_id)
    return token == "LOCKED"


def _vec(tokens, what: str, req_id: int) -> np.ndarray:
    return np.array([parse_float(t, what, req_id) for t in tokens])


def decode_reply(command: str, reply: ReplyLine):
    """The typed result of a reply to `command`; raises TrackerError for ERR replies."""
    f, rid = reply.fields, reply.id
    if not reply.ok:
        if not f or not _CODE.fullmatch(f[0]):
            raise ProtocolError("ERR reply without an upper-case error code", rid)
        raise TrackerError(f[0], " ".join(f[1:]))
    expected = {
        "ID": 3,
        "POINT": 1,
        "SEARCH": 1,
        "MEASURE": 8,
        "STABLE": 8,
        "WEATHER": 3,
        "STATUS": 4,
    }
    if command not in expected:
        raise ValueError(f"unknown command {command!r}")
    if len(f) != expected[command]:
        raise ProtocolError(f"{command} reply needs {expected[command]} fields, got {len(f)}", rid)
    if command == "ID":
        return Ident(*f)
    if command in ("POINT", "SEARCH"):
        return _locked(f[0], rid)
    if command in ("MEASURE", "STABLE"):
        mean, std = _vec(f[0:3], "mean", rid), _vec(f[3:6], "std", rid)
        samples = parse_int(f[6], "samples", rid)
        if np.any(std < 0) or samples < 1 or f[7] not in (MEASURE_OK, MEASURE_INACCURATE):
            raise ProtocolError(f"{command} reply out of range: {' '.join(f)}", rid)
        return Measurement(mean, std, samples, f[7])
    if command == "WEATHER":
        t, p, h = (parse_float(x, "weather", rid) for x in f)
        if p <= 0 or not 0 <= h <= 100:
            raise ProtocolError(f"WEATHER reply out of range: {' '.join(f)}", rid)
        return Weather(t, p, h)
    return Status(_locked(f[0], rid), _vec(f[1:], "aim", rid))


def parse_reply(line: str, command: str, req_id: int):
    """Split, check the id, decode: the whole reply path for one line."""
    reply = split_reply(line)
    if reply.id != req_id:
        raise ProtocolError(f"reply id #{reply.id} does not match request #{req_id}", reply.id)
    return decode_reply(command, reply)
