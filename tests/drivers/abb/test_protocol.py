"""PROTOCOL.md encoders and parsers, checked against tables of lines."""

import math

import pytest

from robocal.drivers.abb import protocol as p

GOOD_REQUESTS = [
    ("#1 HELLO", p.Request(1, "HELLO")),
    ("#5 MOVEJ 10.0 -20.5 30 0 45 90", p.Request(5, "MOVEJ", (10.0, -20.5, 30.0, 0.0, 45.0, 90.0))),
    ("#99999 STATUS", p.Request(99999, "STATUS")),
    ("#7 JOINTS\r\n", p.Request(7, "JOINTS")),
    ("#8  STOP ", p.Request(8, "STOP")),
    ("#9 RESET", p.Request(9, "RESET")),
    ("#3 MOVEJ +.5 -0. 1e2", p.Request(3, "MOVEJ", (0.5, 0.0, 100.0))),
]


@pytest.mark.parametrize("line, expected", GOOD_REQUESTS)
def test_parse_request(line, expected):
    assert p.parse_request(line) == expected


BAD_REQUESTS = [  # line, the id the error can still answer (None: unreadable)
    ("", None),
    ("hello", None),
    ("#", None),
    ("#x HELLO", None),
    ("#-1 HELLO", None),
    ("#123456 HELLO", None),
    ("5 HELLO", None),
    ("\x00\xff#5 HELLO", None),
    ("#5 MOVE" + "J 1" * 40, None),  # longer than 80 characters
    ("#5", 5),
    ("#5 FLY", 5),
    ("#5 hello", 5),
    ("#5 HELLO extra", 5),
    ("#5 STATUS 1", 5),
    ("#5 MOVEJ", 5),
    ("#5 MOVEJ 1 2 3 4 5 6 7", 5),
    ("#5 MOVEJ 1 2 3 nan 5 6", 5),
    ("#5 MOVEJ 1 2 3 inf 5 6", 5),
    ("#5 MOVEJ 1 2 3 -Infinity 5 6", 5),
    ("#5 MOVEJ 1 2 3 1e999 5 6", 5),
    ("#5 MOVEJ 1 2 3 0x10 5 6", 5),
    ("#5 MOVEJ 1 2 3 1,5 5 6", 5),
    ("#5 MOVEJ 1 2 3 . 5 6", 5),
]


@pytest.mark.parametrize("line, request_id", BAD_REQUESTS)
def test_parse_request_refuses(line, request_id):
    with pytest.raises(p.ProtocolError) as info:
        p.parse_request(line)
    assert info.value.request_id == request_id


GOOD_REPLIES = [
    ("#5 OK 3.42", p.Reply(5, ("3.42",))),
    ("#5 OK", p.Reply(5)),
    ("#5 OK INPOS 4\r", p.Reply(5, ("INPOS", "4"))),
    (
        "#5 ERR LIMIT joint 2 200.0000 outside [-95.0000, 155.0000]",
        p.ErrorReply(5, "LIMIT", "joint 2 200.0000 outside [-95.0000, 155.0000]"),
    ),
    ("#5 ERR BUSY", p.ErrorReply(5, "BUSY")),
    ("#0 ERR BAD_REQUEST no  id", p.ErrorReply(0, "BAD_REQUEST", "no id")),
    ("#5 ERR FAULT 50204", p.ErrorReply(5, "FAULT", "50204")),
]


@pytest.mark.parametrize("line, expected", GOOD_REPLIES)
def test_parse_reply(line, expected):
    assert p.parse_reply(line, expect_id=expected.id) == expected


BAD_REPLIES = [
    "",
    "ok",
    "#5",
    "#5 O",  # partial
    "#5 OK 3.4" + "2" * p.MAX_REPLY,  # too long
    "#5 YES",
    "#5 ERR",
    "#5 ERR NOPE something",
    "#5 err LIMIT",
    "\x00\xff\xfe",
    "RobotWare boot",
    "#5 OK \x1b[0m",
]


@pytest.mark.parametrize("line", BAD_REPLIES)
def test_parse_reply_refuses(line):
    with pytest.raises(p.ProtocolError):
        p.parse_reply(line)


def test_wrong_id_is_its_own_error():
    with pytest.raises(p.WrongIdError) as info:
        p.parse_reply("#7 OK", expect_id=5)
    assert info.value.request_id == 7


@pytest.mark.parametrize(
    "line, expected",
    [
        ("#5 OK", "#5 OK"),
        (">>> \x07#5 OK 1.0", "#5 OK 1.0"),
        ("#4 OK 1.#5 OK", "#5 OK"),  # the rest of a reply cut by a timeout, then the next one
        ("garbage", "garbage"),
    ],
)
def test_resync(line, expected):
    assert p.resync(line) == expected


@pytest.mark.parametrize(
    "fields, expected",
    [
        (("IRB2600-SIM", "1", "6"), p.HelloInfo("IRB2600-SIM", 1, 6)),
        (("cell_3.a", "2", "1"), p.HelloInfo("cell_3.a", 2, 1)),
    ],
)
def test_parse_hello(fields, expected):
    assert p.parse_hello(fields) == expected


@pytest.mark.parametrize(
    "fields",
    [
        (),
        ("A", "1"),
        ("A", "1", "7"),
        ("A", "1", "0"),
        ("A", "x", "6"),
        ("A#", "1", "6"),
        ("A", "1", "6", "x"),
    ],
)
def test_parse_hello_refuses(fields):
    with pytest.raises(p.ProtocolError):
        p.parse_hello(fields)


@pytest.mark.parametrize(
    "fields, expected",
    [
        (("IDLE", "0"), p.Status("IDLE", 0)),
        (("MOVING", "17"), p.Status("MOVING", 17)),
        (("INPOS", "17"), p.Status("INPOS", 17)),
        (("STOPPED", "17"), p.Status("STOPPED", 17)),
        (("FAULT", "50204", "17"), p.Status("FAULT", 17, 50204)),
    ],
)
def test_status_round_trip(fields, expected):
    assert p.parse_status(fields) == expected
    assert p.status_fields(expected) == fields


@pytest.mark.parametrize(
    "fields",
    [
        (),
        ("BUSY", "1"),
        ("MOVING",),
        ("MOVING", "1", "2"),
        ("FAULT", "1"),
        ("FAULT", "x", "1"),
        ("INPOS", "-1"),
        ("INPOS", "1.5"),
    ],
)
def test_parse_status_refuses(fields):
    with pytest.raises(p.ProtocolError):
        p.parse_status(fields)


@pytest.mark.parametrize(
    "fields, ok",
    [
        (("3.420",), True),
        (("0",), True),
        (("-1",), False),
        (("nan",), False),
        (("inf",), False),
        ((), False),
        (("1", "2"), False),
    ],
)
def test_parse_duration(fields, ok):
    if ok:
        assert p.parse_duration(fields) == float(fields[0])
    else:
        with pytest.raises(p.ProtocolError):
            p.parse_duration(fields)


def test_parse_joints():
    assert p.parse_joints(("1.5", "-2", "0", "3", "4", "5"), 6) == (1.5, -2.0, 0.0, 3.0, 4.0, 5.0)
    for fields in [("1",) * 5, ("1",) * 7, ("1", "2", "3", "nan", "5", "6")]:
        with pytest.raises(p.ProtocolError):
            p.parse_joints(fields, 6)


def test_encode_request_round_trips_at_4_decimals():
    req = p.Request(99999, "MOVEJ", (-400.0, -179.99994, 155.00004, 1 / 3, -0.00001, 400.0))
    line = p.encode_request(req)
    assert line == "#99999 MOVEJ -400.0000 -179.9999 155.0000 0.3333 0.0000 400.0000"
    assert len(line) <= p.MAX_LINE
    assert p.parse_request(line).values == (-400.0, -179.9999, 155.0, 0.3333, 0.0, 400.0)


@pytest.mark.parametrize(
    "req",
    [
        p.Request(1, "MOVEJ", (1.0, math.nan)),
        p.Request(1, "MOVEJ", (math.inf,)),
        p.Request(1, "MOVEJ", ()),
        p.Request(1, "MOVEJ", (0.0,) * 7),
        p.Request(1, "STATUS", (1.0,)),
        p.Request(0 - 1, "HELLO"),
        p.Request(100000, "HELLO"),
        p.Request(1, "FLY"),
        p.Request(1, "MOVEJ", (1e12,) * 6),  # over 80 characters
    ],
)
def test_encode_request_refuses(req):
    with pytest.raises(p.ProtocolError):
        p.encode_request(req)


def test_encode_error_reply_is_sanitised_and_fits():
    line = p.encode_reply(p.ErrorReply(99999, "BAD_REQUEST", "bad #id \x00\xff " + "x" * 100))
    assert line.startswith("#99999 ERR BAD_REQUEST bad ?id ??")
    assert len(line) == p.MAX_LINE and "#" not in line[1:]
    assert p.parse_reply(line).code == "BAD_REQUEST"


def test_encode_reply_refuses_bad_fields():
    for fields in [("a b",), ("",), ("#3",), ("x" * p.MAX_REPLY,)]:
        with pytest.raises(p.ProtocolError):
            p.encode_reply(p.Reply(1, fields))
    with pytest.raises(p.ProtocolError):
        p.encode_reply(p.ErrorReply(1, "OOPS"))


def test_format_number():
    assert p.format_number(-0.00001, 4) == "0.0000"
    assert p.format_number(-0.0001, 4) == "-0.0001"
    assert p.format_number(3.4199, 3) == "3.420"
    with pytest.raises(p.ProtocolError):
        p.format_number(math.nan, 3)
