"""Hypothesis settings and line strategies shared by the parsers' property tests."""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

# CI runs the same examples every time (a red build is reproducible); a developer's run explores.
FUZZ = settings(
    max_examples=300,
    deadline=None,
    derandomize=os.environ.get("CI") == "true",
    suppress_health_check=[HealthCheck.too_slow],
)

# Tokens that sit on the edges of number, id and text parsing.
EDGE_TOKENS = [
    "",
    "#",
    "#0",
    "#-1",
    "#1",
    "#99999",
    "#100000",
    "#999999999",
    "#1000000000",
    "OK",
    "ERR",
    "0",
    "-0",
    "+1",
    "1.",
    ".5",
    "1e999",
    "-1e999",
    "1e-999",
    "nan",
    "inf",
    "-inf",
    "0x10",
    "1_000",
    "9" * 5000,
    "1" + "0" * 400,
    "\u0661\u0662",  # Arabic-Indic digits: \d in a str pattern matches them
    "\uff11",  # fullwidth 1
    "\u00a0",
    "\x00",
    "\r",
    "\n",
    "\t",
    ",",
    '"',
    ";",
]


def wire(data: bytes) -> str:
    """Bytes as the transports hand them to a parser (ASCII, undecodable bytes replaced)."""
    return data.decode("ascii", errors="replace")


def random_lines() -> st.SearchStrategy[str]:
    """Any text, any bytes as the transports decode them, with or without a line end."""
    raw = st.one_of(st.text(max_size=200), st.binary(max_size=200).map(wire))
    return st.tuples(raw, st.sampled_from(["", "\n", "\r\n", "\r"])).map("".join)


@st.composite
def mutated(draw, valid: st.SearchStrategy[str], sep: str = " ") -> str:
    """A valid line with a few tokens or characters replaced, dropped, doubled or swapped."""
    line = draw(valid)
    end = "\n" if line.endswith("\n") else ""
    tokens = line.removesuffix("\n").split(sep)
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(tokens) - 1))
        op = draw(st.sampled_from(["token", "drop", "double", "swap", "char", "cut"]))
        if op == "token":
            tokens[i] = draw(st.one_of(st.sampled_from(EDGE_TOKENS), st.text(max_size=12)))
        elif op == "drop" and len(tokens) > 1:
            del tokens[i]
        elif op == "double":
            tokens.insert(i, tokens[i])
        elif op == "swap":
            j = draw(st.integers(0, len(tokens) - 1))
            tokens[i], tokens[j] = tokens[j], tokens[i]
        elif op == "char":
            t = tokens[i]
            k = draw(st.integers(0, len(t)))
            c = draw(st.one_of(st.sampled_from("#.-+eE0 9\r\x00\u0661"), st.characters()))
            tokens[i] = t[:k] + c + t[k + 1 :]
        elif op == "cut":
            tokens = tokens[: i + 1]
            tokens[i] = tokens[i][: draw(st.integers(0, len(tokens[i])))]
    return sep.join(tokens) + draw(st.sampled_from([end, "", "\n", "\r\n"]))


def edge_variants(line: str, sep: str = " "):
    """The line with each of its tokens replaced, in turn, by each edge token."""
    end = "\n" if line.endswith("\n") else ""
    tokens = line.removesuffix("\n").split(sep)
    for i in range(len(tokens)):
        for edge in EDGE_TOKENS:
            yield sep.join(tokens[:i] + [edge] + tokens[i + 1 :]) + end
