"""Property tests: whatever line arrives, the ABB parsers answer a value or ProtocolError."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from robocal.drivers.abb import protocol as p
from robocal.drivers.abb.sim import SimulatedController
from robocal.drivers.cell import VirtualCell
from robocal.drivers.clock import VirtualClock
from robocal.drivers.world import SimulatedWorld
from robocal.solver.robot import IRB2600

from ...fuzz import FUZZ, edge_variants, mutated, random_lines
from .conftest import TARGETS

IDS = st.integers(1, p.MAX_ID)
DEG = st.floats(-999.0, 999.0, allow_nan=False)


@st.composite
def requests(draw) -> str:
    command = draw(st.sampled_from(p.COMMANDS))
    values = draw(st.lists(DEG, min_size=1, max_size=p.MAX_JOINTS)) if command == "MOVEJ" else []
    return p.encode_request(p.Request(draw(IDS), command, tuple(values)))


@st.composite
def hello(draw) -> tuple[str, ...]:
    n = draw(st.integers(1, p.MAX_JOINTS))
    lo = draw(st.lists(st.floats(-360.0, 0.0), min_size=n, max_size=n))
    limits = tuple((a, a + 1.0) for a in lo) if draw(st.booleans()) else None
    return p.hello_fields(p.HelloInfo("IRB2600-SIM", p.VERSION, n, limits))


STATUS = st.one_of(
    st.builds(p.Status, st.sampled_from(["IDLE", "MOVING", "INPOS", "STOPPED"]), IDS),
    st.builds(p.Status, st.just("FAULT"), IDS, st.integers(0, 99999)),
).map(p.status_fields)
FIELDS = st.one_of(
    hello(),
    STATUS,
    st.lists(DEG, min_size=1, max_size=p.MAX_JOINTS).map(p.joints_fields),
    st.floats(0.0, 100.0).map(p.duration_fields),
    st.just(()),
)
replies = st.one_of(
    st.builds(p.Reply, IDS, FIELDS),
    st.builds(p.ErrorReply, IDS, st.sampled_from(p.ERROR_CODES), st.text(max_size=40)),
).map(lambda r: p.encode_reply(r) + "\n")


def only_protocol_errors(parse, line):
    try:
        parse(line)
    except p.ProtocolError:
        pass


def read_reply(line: str) -> None:
    """The client's whole reading of a line: the reply, then each typed payload it may carry."""
    reply = p.parse_reply(p.resync(line), expect_id=None)
    if isinstance(reply, p.Reply):
        for parse in (
            p.parse_hello,
            p.parse_status,
            p.parse_duration,
            lambda f: p.parse_joints(f, 6),
            lambda f: p.parse_empty(f, "STOP"),
        ):
            only_protocol_errors(parse, reply.fields)


@FUZZ
@given(st.one_of(random_lines(), mutated(requests())))
def test_request_parser_raises_only_protocol_errors(line):
    only_protocol_errors(p.parse_request, line)


@FUZZ
@given(st.one_of(random_lines(), mutated(replies)))
def test_reply_parsers_raise_only_protocol_errors(line):
    only_protocol_errors(read_reply, line)
    only_protocol_errors(lambda text: p.parse_reply(text, expect_id=7), line)


@FUZZ
@given(requests(), replies)
def test_the_lines_mutated_above_are_valid(request, reply):
    assert p.encode_request(p.parse_request(request)) == request
    read_reply(reply)


REQUESTS = ["#7 HELLO", "#7 MOVEJ 10.0000 -20.5000 30.0000 0.0000 45.0000 -90.0000", "#7 STOP"]
REPLIES = [
    "#7 OK IRB2600-SIM 1 6 -180 180 -95 155 -180 75 -400 400 -120 120 -400 400",
    "#7 OK FAULT 50204 12",
    "#7 OK IDLE 12",
    "#7 OK 1.0000 2.0000 3.0000 4.0000 5.0000 6.0000",
    "#7 OK 1.250",
    "#7 ERR LIMIT joint 2 outside its limits",
]


def test_every_field_of_every_line_takes_every_edge_token():
    for line in REQUESTS:
        p.parse_request(line)
        for variant in edge_variants(line):
            only_protocol_errors(p.parse_request, variant)
    for line in REPLIES:
        for variant in [line, *edge_variants(line)]:
            only_protocol_errors(read_reply, variant)


clock = VirtualClock()
DEVICE = SimulatedController(
    SimulatedWorld(VirtualCell.random(IRB2600, TARGETS, seed=1), clock), IRB2600, clock
)


@FUZZ
@given(st.one_of(random_lines(), mutated(requests())))
def test_simulated_controller_answers_every_line_with_a_reply(line):
    reply = p.parse_reply(DEVICE.handle_line(line))
    assert isinstance(reply, p.Reply) or reply.code in p.ERROR_CODES
