"""Property tests: whatever line arrives, the tracker parsers answer a value or ProtocolError."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from robocal.drivers.tracker.protocol import (
    COMMANDS,
    MAX_ID,
    MAX_STABLE_WAIT_S,
    Ident,
    Measurement,
    ProtocolError,
    Status,
    TrackerError,
    Weather,
    decode_reply,
    encode_reply,
    encode_request,
    parse_reply,
    parse_request,
    split_reply,
)

from ...fuzz import FUZZ, edge_variants, mutated, random_lines
from .conftest import make_rig

IDS = st.integers(1, MAX_ID)
MM = st.floats(-1e4, 1e4, allow_nan=False)
TOKEN = st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=12)


@st.composite
def requests(draw) -> str:
    command = draw(st.sampled_from(sorted(COMMANDS)))
    # STABLE's float is its wait, bounded tighter than a coordinate or a search radius
    high = MAX_STABLE_WAIT_S if command == "STABLE" else 200.0
    args = [
        draw(st.integers(1, 100_000) if kind is int else st.floats(0.1, high))
        for kind in COMMANDS[command]
    ]
    return encode_request(draw(IDS), command, *args)


def vec3():
    return st.lists(MM, min_size=3, max_size=3).map(np.array)


REPLY_VALUES = st.one_of(
    st.builds(Ident, TOKEN, TOKEN, TOKEN),
    st.booleans(),
    st.builds(
        Measurement,
        vec3(),
        vec3().map(np.abs),
        st.integers(1, 100_000),
        st.sampled_from(["OK", "INACCURATE"]),
    ),
    st.builds(Weather, MM, st.floats(1.0, 2000.0), st.floats(0.0, 100.0)),
    st.builds(Status, st.booleans(), vec3()),
    st.builds(TrackerError, st.sampled_from(["BUSY", "BAD_REQUEST"]), st.text(max_size=30)),
)
replies = st.builds(encode_reply, IDS, REPLY_VALUES)


def reader(command: str):
    """The client's reading of a reply line to `command`."""
    return lambda line: decode_reply(command, split_reply(line))


def only_protocol_errors(parse, line):
    """Run parse(line); a ProtocolError (or a device's TrackerError) is the only way out."""
    try:
        parse(line)
    except (ProtocolError, TrackerError):
        pass


@FUZZ
@given(st.one_of(random_lines(), mutated(requests())))
def test_request_parser_raises_only_protocol_errors(line):
    only_protocol_errors(parse_request, line)


@FUZZ
@given(st.one_of(random_lines(), mutated(replies)), st.sampled_from(sorted(COMMANDS)))
def test_reply_parser_raises_only_protocol_errors(line, command):
    only_protocol_errors(reader(command), line)
    only_protocol_errors(lambda text: parse_reply(text, command, 1), line)


@FUZZ
@given(requests())
def test_valid_requests_and_replies_parse(line):
    # the mutations above start from lines the parsers accept, or they would test nothing
    req = parse_request(line)
    assert encode_request(req.id, req.command, *req.args) == line


# One valid line per command and reply kind, to take apart token by token.
REQUESTS = [
    "#7 ID\n",
    "#7 POINT 1.000000 -2.500000 3000.000000\n",
    "#7 SEARCH 20.000000\n",
    "#7 MEASURE 500\n",
    "#7 STABLE 1000 10\n",
    "#7 WEATHER\n",
    "#7 STATUS\n",
]
REPLIES = [
    "#7 OK AT960 123 1.2\n",
    "#7 OK LOCKED\n",
    "#7 OK 1.0 2.0 3.0 0.01 0.02 0.03 500 OK\n",
    "#7 OK 20.5 1013.2 45.0\n",
    "#7 OK UNLOCKED 1.0 2.0 3.0\n",
    "#7 ERR TARGET_NOT_FOUND no target within 20 mm\n",
]


def test_every_field_of_every_line_takes_every_edge_token():
    for line in REQUESTS:
        parse_request(line)
        for variant in edge_variants(line):
            only_protocol_errors(parse_request, variant)
    for line in REPLIES:
        for command in COMMANDS:
            for variant in [line, *edge_variants(line)]:
                only_protocol_errors(reader(command), variant)


RIG = make_rig()


@FUZZ
@given(st.one_of(random_lines(), mutated(requests())))
def test_simulated_tracker_answers_every_line_with_a_reply(line):
    reply = split_reply(RIG.dev.handle(line))
    assert reply.ok or reply.fields[0] in ("BAD_REQUEST", "TARGET_NOT_FOUND", "BEAM_BROKEN")
