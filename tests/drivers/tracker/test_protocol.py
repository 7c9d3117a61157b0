"""The line protocol: tables of good and bad request and reply lines, and round trips."""

import numpy as np
import pytest

from robocal.drivers.tracker.protocol import (
    Ident,
    Measurement,
    ProtocolError,
    Request,
    Status,
    TrackerError,
    Weather,
    encode_reply,
    encode_request,
    parse_reply,
    parse_request,
    search_time_s,
)

GOOD_REPLIES = [
    ("ID", "#1 OK FARO-Vantage S1234 2.4.1\n", Ident("FARO-Vantage", "S1234", "2.4.1")),
    ("POINT", "#1 OK LOCKED\n", True),
    ("POINT", "#1 OK UNLOCKED\r\n", False),
    ("POINT", "#1  OK   LOCKED\n", True),  # runs of spaces separate fields too
    ("SEARCH", "#1 OK LOCKED\n", True),
    ("WEATHER", "#1 OK 20.5 1013.25 45\n", Weather(20.5, 1013.25, 45.0)),
    ("WEATHER", "#1 OK -5 800 0\n", Weather(-5.0, 800.0, 0.0)),
]

BAD_REPLIES = [  # (command, line, awaited id, part of the message)
    ("POINT", "", 1, "partial"),
    ("POINT", "#1 OK LOCKED", 1, "partial"),
    ("POINT", "#1 OK LOC", 1, "partial"),
    ("POINT", "garbage\n", 1, "missing request id"),
    ("POINT", "\ufffd\ufffd#1 OK LOCKED\n", 1, "not printable"),
    ("POINT", "#1 OK LOCKED\x00\n", 1, "not printable"),
    ("POINT", "#1 OK\tLOCKED\n", 1, "not printable"),
    ("POINT", "#1 OK LOCKED\n#2 OK LOCKED\n", 1, "not printable"),  # two lines are not one
    ("POINT", "1 OK LOCKED\n", 1, "missing request id"),
    ("POINT", "#x OK LOCKED\n", 1, "missing request id"),
    ("POINT", "#-1 OK LOCKED\n", 1, "missing request id"),
    ("POINT", "#1234567890 OK LOCKED\n", 1, "missing request id"),
    ("POINT", "#2 OK LOCKED\n", 1, "does not match"),
    ("POINT", "#1\n", 1, "OK or ERR"),
    ("POINT", "#1 YES LOCKED\n", 1, "OK or ERR"),
    ("POINT", "#1 ok LOCKED\n", 1, "OK or ERR"),
    ("POINT", "#1 OK\n", 1, "needs 1 fields"),
    ("POINT", "#1 OK LOCKED NOW\n", 1, "needs 1 fields"),
    ("POINT", "#1 OK MAYBE\n", 1, "LOCKED or UNLOCKED"),
    ("ID", "#1 OK SimTracker SIM-0001\n", 1, "needs 3 fields"),
    ("MEASURE", "#4 OK 1.5 -2 3e2 0.007 0.006\n", 4, "needs 8 fields"),
    ("MEASURE", "#4 OK 1.5 -2 3e2 0.007 0.006 0.007 500 OK extra\n", 4, "needs 8 fields"),
    ("MEASURE", "#4 OK nan -2 3 0.007 0.006 0.007 500 OK\n", 4, "not a number"),
    ("MEASURE", "#4 OK 1 inf 3 0.007 0.006 0.007 500 OK\n", 4, "not a number"),
    ("MEASURE", "#4 OK 1 -2 1e999 0.007 0.006 0.007 500 OK\n", 4, "not finite"),
    ("MEASURE", "#4 OK 0x10 -2 3 0.007 0.006 0.007 500 OK\n", 4, "not a number"),
    ("MEASURE", "#4 OK 1_000 -2 3 0.007 0.006 0.007 500 OK\n", 4, "not a number"),
    ("MEASURE", "#4 OK --1 -2 3 0.007 0.006 0.007 500 OK\n", 4, "not a number"),
    ("MEASURE", "#4 OK 1 -2 3 -0.007 0.006 0.007 500 OK\n", 4, "out of range"),
    ("MEASURE", "#4 OK 1 -2 3 0.007 0.006 0.007 5.0 OK\n", 4, "integer"),
    ("MEASURE", "#4 OK 1 -2 3 0.007 0.006 0.007 0 OK\n", 4, "out of range"),
    ("MEASURE", "#4 OK 1 -2 3 0.007 0.006 0.007 500 GOOD\n", 4, "out of range"),
    ("WEATHER", "#1 OK 20 1013 120\n", 1, "out of range"),
    ("WEATHER", "#1 OK 20 -1 45\n", 1, "out of range"),
    ("WEATHER", "#1 OK 20 1013 forty\n", 1, "not a number"),
    ("STATUS", "#1 OK LOCKED 1 2 nan\n", 1, "not a number"),
    ("STATUS", "#1 OK 1 2 3\n", 1, "needs 4 fields"),
    ("STATUS", "#1 ERR\n", 1, "error code"),
    ("STATUS", "#1 ERR oops lower case\n", 1, "error code"),
]


@pytest.mark.parametrize("command, line, expected", GOOD_REPLIES)
def test_good_replies(command, line, expected):
    assert parse_reply(line, command, 1) == expected


def test_measure_and_status_replies():
    m = parse_reply("#4 OK 1.5 -2 3e2 0.007 0.006 .0071 500 INACCURATE\n", "MEASURE", 4)
    np.testing.assert_array_equal(m.mean_mm, [1.5, -2.0, 300.0])
    np.testing.assert_array_equal(m.std_mm, [0.007, 0.006, 0.0071])
    assert (m.samples, m.status, m.ok) == (500, "INACCURATE", False)
    s = parse_reply("#9 OK UNLOCKED 1000 -2.5 +3\n", "STATUS", 9)
    assert not s.locked
    np.testing.assert_array_equal(s.aim_mm, [1000.0, -2.5, 3.0])


@pytest.mark.parametrize("command, line, req_id, message", BAD_REPLIES)
def test_bad_replies_are_refused(command, line, req_id, message):
    with pytest.raises(ProtocolError, match=message):
        parse_reply(line, command, req_id)


@pytest.mark.parametrize(
    "line, code, message",
    [
        (
            "#5 ERR TARGET_NOT_FOUND no target within 10 mm\n",
            "TARGET_NOT_FOUND",
            "no target within 10 mm",
        ),
        ("#5 ERR BEAM_BROKEN\n", "BEAM_BROKEN", ""),
        ("#5 ERR LASER_COLD warming up\n", "LASER_COLD", "warming up"),  # unknown codes still raise
    ],
)
def test_error_replies_raise_tracker_error(line, code, message):
    with pytest.raises(TrackerError) as info:
        parse_reply(line, "MEASURE", 5)
    assert (info.value.code, info.value.message) == (code, message)


GOOD_REQUESTS = [
    ("#17 MEASURE 500\n", Request(17, "MEASURE", (500,))),
    ("#2 POINT 1 -2.5 3e3\n", Request(2, "POINT", (1.0, -2.5, 3000.0))),
    ("#3 SEARCH 10\n", Request(3, "SEARCH", (10.0,))),
    ("#4 ID\r\n", Request(4, "ID")),
    ("#5 WEATHER\n", Request(5, "WEATHER")),
    ("#6 STATUS\n", Request(6, "STATUS")),
]

BAD_REQUESTS = [  # (line, id the error can still name, part of the message)
    ("#17 MEASURE 500", None, "partial"),
    ("MEASURE 500\n", None, "missing request id"),
    ("\ufffd#1 ID\n", None, "not printable"),
    ("#17\n", 17, "missing command"),
    ("#17 measure 5\n", 17, "unknown command"),
    ("#17 FIRE\n", 17, "unknown command"),
    ("#17 ID extra\n", 17, "takes 0 arguments"),
    ("#17 MEASURE\n", 17, "takes 1 arguments"),
    ("#17 MEASURE 0\n", 17, "1..100000"),
    ("#17 MEASURE 100001\n", 17, "1..100000"),
    ("#17 MEASURE 5.5\n", 17, "integer"),
    ("#17 MEASURE -5\n", 17, "integer"),
    ("#17 POINT 1 2\n", 17, "takes 3 arguments"),
    ("#17 POINT 1 2 nan\n", 17, "not a number"),
    ("#17 POINT 1 2 1e400\n", 17, "not finite"),
    ("#17 SEARCH 0\n", 17, "SEARCH radius"),
    ("#17 SEARCH -5\n", 17, "SEARCH radius"),
    ("#17 SEARCH 500\n", 17, "SEARCH radius"),
]


@pytest.mark.parametrize("line, expected", GOOD_REQUESTS)
def test_good_requests(line, expected):
    assert parse_request(line) == expected


@pytest.mark.parametrize("line, req_id, message", BAD_REQUESTS)
def test_bad_requests_are_refused(line, req_id, message):
    with pytest.raises(ProtocolError, match=message) as info:
        parse_request(line)
    assert info.value.request_id == req_id


@pytest.mark.parametrize(
    "command, args",
    [
        ("ID", ()),
        ("POINT", (1523.25, -402.1, 880.0)),
        ("SEARCH", (10.0,)),
        ("MEASURE", (500,)),
        ("WEATHER", ()),
        ("STATUS", ()),
    ],
)
def test_requests_round_trip(command, args):
    assert parse_request(encode_request(42, command, *args)) == Request(42, command, args)


@pytest.mark.parametrize(
    "req_id, command, args",
    [
        (0, "ID", ()),
        (1_000_000_000, "ID", ()),
        (1, "FIRE", ()),
        (1, "POINT", (1.0, 2.0)),
        (1, "POINT", (1.0, 2.0, float("nan"))),
    ],
)
def test_encode_request_refuses_bad_input(req_id, command, args):
    with pytest.raises(ValueError):
        encode_request(req_id, command, *args)


def test_replies_round_trip():
    m = Measurement(
        np.array([1523.251234, -402.098765, 880.001111]),
        np.array([0.007102, 0.006954, 0.007311]),
        500,
        "OK",
    )
    back = parse_reply(encode_reply(7, m), "MEASURE", 7)
    np.testing.assert_allclose(back.mean_mm, m.mean_mm, atol=1e-6)
    np.testing.assert_allclose(back.std_mm, m.std_mm, atol=1e-6)
    assert (back.samples, back.status) == (500, "OK")
    assert parse_reply(encode_reply(7, Ident("Sim", "S1", "1.0")), "ID", 7) == Ident(
        "Sim", "S1", "1.0"
    )
    assert parse_reply(encode_reply(7, True), "POINT", 7) is True
    assert parse_reply(encode_reply(7, False), "POINT", 7) is False
    assert parse_reply(encode_reply(7, Weather(20.1, 1013.2, 45.0)), "WEATHER", 7) == Weather(
        20.1, 1013.2, 45.0
    )
    s = parse_reply(encode_reply(7, Status(True, np.array([1.0, 2.0, 3.0]))), "STATUS", 7)
    assert s.locked and np.allclose(s.aim_mm, [1, 2, 3])


def test_error_reply_round_trip_and_sanitised_message():
    line = encode_reply(3, TrackerError("BEAM_BROKEN", "lost\nbeam \u00e9"))
    assert line == "#3 ERR BEAM_BROKEN lost?beam ?\n"
    with pytest.raises(TrackerError, match="BEAM_BROKEN"):
        parse_reply(line, "MEASURE", 3)


def test_search_time_grows_with_radius():
    assert search_time_s(10) == pytest.approx(0.2 + np.pi * 0.1)
    assert search_time_s(50) > 20 * (search_time_s(10) - 0.2)
