"""The robocal ABB line protocol (PROTOCOL.md): pure encoders and parsers, no I/O."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ..line_errors import ProtocolError

VERSION = 1
MAX_LINE = 80  # a RAPID string holds at most 80 characters: the most a request may take
MAX_REPLY = 200  # RAPID writes replies from rawbytes: room for a HELLO with its limit table
MAX_ID = 99999  # exact in RAPID's num, and short enough to keep a 6-axis MOVEJ under MAX_LINE
MAX_JOINTS = 6  # jointtarget.robax; a 7th value would not fit in MAX_LINE at 4 decimals
ANGLE_DECIMALS = 4
DURATION_DECIMALS = 3

COMMANDS = ("HELLO", "MOVEJ", "STATUS", "JOINTS", "STOP", "RESET")
ERROR_CODES = ("LIMIT", "BUSY", "FAULT", "BAD_REQUEST")
STATES = ("IDLE", "MOVING", "INPOS", "STOPPED", "FAULT")

_ID = re.compile(r"#(\d{1,5})")
_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?")
_INT = re.compile(r"\d{1,9}")
_NAME = re.compile(r"[A-Za-z0-9_.\-]{1,32}")


class WrongIdError(ProtocolError):
    """A well-formed reply to some other request (typically a late reply to a timed-out one)."""


@dataclass(frozen=True)
class Request:
    """`#<id> <COMMAND> [values]`; only MOVEJ carries values (joint angles, degrees)."""

    id: int
    command: str
    values: tuple[float, ...] = ()


@dataclass(frozen=True)
class Reply:
    """`#<id> OK [fields]`; the fields' meaning depends on the request (see the parse_* helpers)."""

    id: int
    fields: tuple[str, ...] = ()


@dataclass(frozen=True)
class ErrorReply:
    """`#<id> ERR <CODE> [message]`."""

    id: int
    code: str
    message: str = ""


@dataclass(frozen=True)
class HelloInfo:
    """What HELLO returns: who the controller is and how many joints it drives."""

    name: str
    version: int
    n_joints: int
    limits_deg: tuple[tuple[float, float], ...] | None = None  # per joint (lo, hi); None: not sent


@dataclass(frozen=True)
class Status:
    """What STATUS returns; `move_id` is the request id of the last accepted MOVEJ (0: none yet)."""

    state: str
    move_id: int
    fault_code: int | None = None


# --- lines --------------------------------------------------------------------------------------


def _check_line(line: str, limit: int = MAX_LINE) -> str:
    line = line.rstrip("\r\n")
    if len(line) > limit:
        raise ProtocolError(f"line of {len(line)} characters, at most {limit}")
    if not line.isascii() or not line.isprintable():
        raise ProtocolError("non-printable or non-ASCII characters")
    return line


def _parse_id(token: str) -> int:
    m = _ID.fullmatch(token)
    if not m:
        raise ProtocolError(f"expected '#<id>', got {token[:12]!r}")
    return int(m.group(1))


def _check_id(request_id: int) -> None:
    if not (isinstance(request_id, int) and 0 <= request_id <= MAX_ID):
        raise ProtocolError(f"request id {request_id!r} outside 0..{MAX_ID}")


def parse_number(token: str) -> float:
    """A finite decimal number; nan, inf and overflowing exponents are refused."""
    if not _NUMBER.fullmatch(token):
        raise ProtocolError(f"not a number: {token[:16]!r}")
    value = float(token)
    if not math.isfinite(value):
        raise ProtocolError(f"number out of range: {token[:16]!r}")
    return value


def parse_int(token: str) -> int:
    if not _INT.fullmatch(token):
        raise ProtocolError(f"not a non-negative integer: {token[:16]!r}")
    return int(token)


def format_number(value: float, decimals: int) -> str:
    """Fixed-point text; refuses non-finite values and never writes '-0.0000'."""
    value = float(value)
    if not math.isfinite(value):
        raise ProtocolError(f"non-finite value {value!r}")
    text = f"{value:.{decimals}f}"
    return text[1:] if text.lstrip("-0.") == "" and text.startswith("-") else text


def resync(line: str) -> str:
    """The line from its last '#', dropping noise glued in front of a reply ('#' is only first)."""
    i = line.rfind("#")
    return line[i:] if i > 0 else line


# --- requests -----------------------------------------------------------------------------------


def encode_request(req: Request) -> str:
    """The request line, without its newline."""
    _check_id(req.id)
    if req.command not in COMMANDS:
        raise ProtocolError(f"unknown command {req.command!r}")
    if req.command == "MOVEJ":
        if not 1 <= len(req.values) <= MAX_JOINTS:
            raise ProtocolError(f"MOVEJ takes 1..{MAX_JOINTS} values, got {len(req.values)}")
    elif req.values:
        raise ProtocolError(f"{req.command} takes no values")
    parts = [f"#{req.id}", req.command] + [format_number(v, ANGLE_DECIMALS) for v in req.values]
    line = " ".join(parts)
    if len(line) > MAX_LINE:
        raise ProtocolError(f"request of {len(line)} characters, at most {MAX_LINE}")
    return line


def parse_request(line: str) -> Request:
    """A request line as the controller reads it."""
    tokens = _check_line(line).split()
    if not tokens:
        raise ProtocolError("empty line")
    request_id = _parse_id(tokens[0])
    if len(tokens) < 2:
        raise ProtocolError("missing command", request_id)
    command, args = tokens[1], tokens[2:]
    if command not in COMMANDS:
        raise ProtocolError(f"unknown command {command[:16]!r}", request_id)
    if command != "MOVEJ":
        if args:
            raise ProtocolError(f"{command} takes no arguments", request_id)
        return Request(request_id, command)
    if not 1 <= len(args) <= MAX_JOINTS:
        raise ProtocolError(f"MOVEJ takes 1..{MAX_JOINTS} values, got {len(args)}", request_id)
    try:
        values = tuple(parse_number(a) for a in args)
    except ProtocolError as exc:
        raise ProtocolError(str(exc), request_id) from None
    return Request(request_id, command, values)


# --- replies ------------------------------------------------------------------------------------


def _clean_message(message: str, room: int) -> str:
    # Messages may quote what the peer sent: keep them printable ASCII, '#'-free (resync), short.
    text = "".join(c if c.isascii() and c.isprintable() and c != "#" else "?" for c in message)
    return " ".join(text.split())[: max(0, room)].rstrip()


def encode_reply(reply: Reply | ErrorReply) -> str:
    """The reply line, without its newline; error messages are sanitised and truncated to fit."""
    _check_id(reply.id)
    if isinstance(reply, ErrorReply):
        if reply.code not in ERROR_CODES:
            raise ProtocolError(f"unknown error code {reply.code!r}")
        head = f"#{reply.id} ERR {reply.code}"
        message = _clean_message(reply.message, MAX_LINE - len(head) - 1)
        return f"{head} {message}" if message else head
    line = " ".join([f"#{reply.id}", "OK", *reply.fields])
    _check_line(line, MAX_REPLY)
    if "#" in line[1:] or any(not f or f != f.strip() or " " in f for f in reply.fields):
        raise ProtocolError(f"bad reply fields {reply.fields!r}")
    return line


def parse_reply(line: str, expect_id: int | None = None) -> Reply | ErrorReply:
    """A reply line as the client reads it; raises WrongIdError if it answers another request."""
    tokens = _check_line(line, MAX_REPLY).split()
    if len(tokens) < 2:
        raise ProtocolError(f"not a reply: {line[:20]!r}")
    reply_id = _parse_id(tokens[0])
    if tokens[1] == "OK":
        reply: Reply | ErrorReply = Reply(reply_id, tuple(tokens[2:]))
    elif tokens[1] == "ERR":
        if len(tokens) < 3 or tokens[2] not in ERROR_CODES:
            raise ProtocolError(f"unknown error code in {line[:30]!r}", reply_id)
        reply = ErrorReply(reply_id, tokens[2], " ".join(tokens[3:]))
    else:
        raise ProtocolError(f"expected OK or ERR, got {tokens[1][:16]!r}", reply_id)
    if expect_id is not None and reply_id != expect_id:
        raise WrongIdError(f"reply to #{reply_id}, expected #{expect_id}", reply_id)
    return reply


# --- typed payloads -----------------------------------------------------------------------------


def _expect(fields, n: int, what: str) -> None:
    if len(fields) != n:
        raise ProtocolError(f"{what}: expected {n} fields, got {len(fields)}")


def format_limit(value_deg: float) -> str:
    """A joint limit in degrees: 4 decimals, trailing zeros dropped ("155", "-179.5")."""
    text = format_number(value_deg, ANGLE_DECIMALS).rstrip("0").rstrip(".")
    return "0" if text in ("", "-") else text


def hello_fields(info: HelloInfo) -> tuple[str, ...]:
    if not _NAME.fullmatch(info.name):
        raise ProtocolError(f"controller name {info.name!r} must match {_NAME.pattern}")
    head = (info.name, str(info.version), str(info.n_joints))
    if info.limits_deg is None:
        return head
    if len(info.limits_deg) != info.n_joints:
        raise ProtocolError(f"{len(info.limits_deg)} limit pairs for {info.n_joints} joints")
    return head + tuple(format_limit(v) for pair in info.limits_deg for v in pair)


def parse_hello(fields) -> HelloInfo:
    """`<name> <version> <n_joints>`, optionally followed by `<lo> <hi>` per joint (degrees)."""
    if len(fields) < 3:
        raise ProtocolError(f"HELLO: expected at least 3 fields, got {len(fields)}")
    name, version, n = fields[:3]
    if not _NAME.fullmatch(name):
        raise ProtocolError(f"bad controller name {name[:16]!r}")
    n_joints = parse_int(n)
    if not 1 <= n_joints <= MAX_JOINTS:
        raise ProtocolError(f"joint count {n_joints} outside 1..{MAX_JOINTS}")
    rest = fields[3:]
    if not rest:
        return HelloInfo(name, parse_int(version), n_joints)
    _expect(rest, 2 * n_joints, "HELLO limits")
    values = [parse_number(f) for f in rest]
    limits = tuple(zip(values[0::2], values[1::2], strict=True))
    for i, (lo, hi) in enumerate(limits, start=1):
        if not lo < hi:
            raise ProtocolError(f"HELLO: joint {i} limits [{lo:g}, {hi:g}] are empty")
    return HelloInfo(name, parse_int(version), n_joints, limits)


def duration_fields(duration_s: float) -> tuple[str, ...]:
    return (format_number(duration_s, DURATION_DECIMALS),)


def parse_duration(fields) -> float:
    _expect(fields, 1, "MOVEJ")
    duration = parse_number(fields[0])
    if duration < 0:
        raise ProtocolError(f"negative duration {duration}")
    return duration


def status_fields(status: Status) -> tuple[str, ...]:
    if status.state not in STATES:
        raise ProtocolError(f"unknown state {status.state!r}")
    if (status.state == "FAULT") != (status.fault_code is not None):
        raise ProtocolError("a fault code goes with the FAULT state, and only with it")
    code = () if status.fault_code is None else (str(int(status.fault_code)),)
    return (status.state, *code, str(int(status.move_id)))


def parse_status(fields) -> Status:
    if not fields or fields[0] not in STATES:
        raise ProtocolError(f"unknown state in {' '.join(fields)[:30]!r}")
    if fields[0] == "FAULT":
        _expect(fields, 3, "STATUS FAULT")
        return Status("FAULT", parse_int(fields[2]), parse_int(fields[1]))
    _expect(fields, 2, "STATUS")
    return Status(fields[0], parse_int(fields[1]))


def joints_fields(q_deg) -> tuple[str, ...]:
    return tuple(format_number(v, ANGLE_DECIMALS) for v in q_deg)


def parse_joints(fields, n_joints: int) -> tuple[float, ...]:
    _expect(fields, n_joints, "JOINTS")
    return tuple(parse_number(f) for f in fields)


def parse_empty(fields, what: str) -> None:
    _expect(fields, 0, what)
