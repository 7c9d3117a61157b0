"""Static checks of the RAPID server: its block structure, and agreement with PROTOCOL.md."""

import re
from pathlib import Path

import numpy as np
import pytest

from robocal.drivers.abb import protocol as p
from robocal.drivers.world import ACCEL_S, DEFAULT_SPEEDS_DEG_S
from robocal.solver.robot import IRB2600

MOD = Path(__file__).parents[3] / "drivers" / "abb" / "rapid" / "RobocalServer.mod"
SOURCE = MOD.read_text(encoding="ascii")
STRINGS = re.findall(r'"((?:[^"]|"")*)"', SOURCE)


def code_lines():
    """Source lines without comments and with string literals blanked."""
    for raw in SOURCE.splitlines():
        line = re.sub(r'"(?:[^"]|"")*"', '""', raw)
        yield line.split("!", 1)[0].strip()


def words():
    return [w for line in code_lines() for w in re.findall(r"[A-Za-z_]\w*", line)]


def const_array(name):
    m = re.search(rf"CONST num {name}\{{6\}} := \[([^\]]*)\];", SOURCE)
    return np.array([float(v) for v in m.group(1).split(",")])


def const(name):
    return re.search(rf"CONST \w+ {name} := ([^;]*);", SOURCE).group(1).strip('"')


def test_module_frame():
    lines = [line for line in code_lines() if line]
    assert lines[0] == "MODULE RobocalServer" and lines[-1] == "ENDMODULE"
    assert "PROC main()" in lines


@pytest.mark.parametrize(
    "opening, closing",
    [
        ("PROC", "ENDPROC"),
        ("FUNC", "ENDFUNC"),
        ("TRAP", "ENDTRAP"),
        ("WHILE", "ENDWHILE"),
        ("FOR", "ENDFOR"),
        ("TEST", "ENDTEST"),
        ("MODULE", "ENDMODULE"),
    ],
)
def test_blocks_balance(opening, closing):
    w = words()
    assert w.count(opening) == w.count(closing) > 0


def test_if_blocks_balance():
    lines = list(code_lines())
    block_ifs = sum(
        1
        for line in lines
        if re.match(r"(ELSE)?IF\b.*\bTHEN$", line) and not line.startswith("ELSEIF")
    )
    assert block_ifs == sum(1 for line in lines if line == "ENDIF")


def test_statements_end_with_semicolons():
    keywords = (
        "MODULE",
        "ENDMODULE",
        "PROC",
        "LOCAL PROC",
        "FUNC",
        "LOCAL FUNC",
        "LOCAL TRAP",
        "ENDPROC",
        "ENDFUNC",
        "ENDTRAP",
        "ERROR",
        "ELSE",
        "DEFAULT:",
        "CASE",
        "TEST",
        "ENDIF",
        "ENDWHILE",
        "ENDFOR",
        "ENDTEST",
    )
    lines = [line for line in code_lines() if line]
    # RAPID closes compound statements without a semicolon
    assert not [line for line in lines if re.fullmatch(r"END(IF|WHILE|FOR|TEST);", line)]
    for line, following in zip(lines, lines[1:] + [""], strict=True):
        ok = (
            line.endswith(";")
            or line.endswith("THEN")
            or line.endswith(" DO")
            or line.startswith(keywords)
            or following.startswith("+")
        )
        assert ok, line


def test_strings_fit_rapid():
    assert all(len(s) <= 80 for s in STRINGS)


def test_limits_speeds_match_the_model_and_the_simulator():
    np.testing.assert_allclose(const_array("LIM_LO"), np.rad2deg(IRB2600.lower))
    np.testing.assert_allclose(const_array("LIM_HI"), np.rad2deg(IRB2600.upper))
    np.testing.assert_allclose(const_array("AXIS_SPEED"), DEFAULT_SPEEDS_DEG_S)
    assert float(const("ACCEL_S")) == ACCEL_S


def test_speaks_protocol_md():
    assert const("PROTOCOL_VERSION") == str(p.VERSION)
    assert re.fullmatch(r"[A-Za-z0-9_.\-]{1,32}", const("CONTROLLER_NAME"))
    for command in p.COMMANDS:
        assert f'cmd = "{command}"' in SOURCE
    for code in p.ERROR_CODES:
        assert any(s.startswith(f"ERR {code}") for s in STRINGS), code
    for state in p.STATES:
        assert f'RETURN "{state}";' in SOURCE
    assert "NumToStr(dur, 3)" in SOURCE and "NumToStr(now.robax.rax_6, 4)" in SOURCE


def test_safety_order_in_movej():
    start = SOURCE.index("PROC DoMoveJ")
    body = SOURCE[start : SOURCE.index("ENDPROC", start)]
    assert body.index("LIM_LO{i}") < body.index("MoveAbsJ")
    assert body.index('"MOVING"') < body.index("MoveAbsJ")
    assert "fine" in body[body.index("MoveAbsJ") :]


def test_every_local_routine_is_used():
    defined = re.findall(r"LOCAL (?:PROC|FUNC \w+|TRAP) (\w+)", SOURCE)
    w = words()
    for name in defined:
        assert w.count(name) >= 2, name


def routine(name):
    start = re.search(rf"(PROC|FUNC \w+) {name}\(", SOURCE).start()
    return SOURCE[start : SOURCE.index("END", SOURCE.index(")", start))]


def test_hello_reports_the_limit_table():
    body = routine("SendHello")
    assert "FOR i FROM 1 TO N_JOINTS DO" in body
    assert "NumToStr(LIM_LO{i}, 4)" in body and "NumToStr(LIM_HI{i}, 4)" in body
    assert "SendHello id;" in SOURCE


def test_a_new_connection_preempts_a_hung_client():
    serve = SOURCE[SOURCE.index("PROC ServeClient") : SOURCE.index("PROC StartClient")]
    # Lines of the served client first, then a newer client takes over: a STOP sent on a new
    # connection waits at most one receive poll and one accept poll.
    assert (
        serve.index("ReadLine(line)")
        < serve.index("NewClient()")
        < serve.index("current := 3 - current")
    )
    assert float(const("POLL_S")) <= 0.05
    assert routine("NewClient").count("\\Time:=POLL_S") == 2
    assert routine("ReadLine").count("\\Time:=POLL_S") == 2
    assert "WAIT_MAX" not in serve
