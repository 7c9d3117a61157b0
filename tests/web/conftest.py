"""A real uvicorn serving the API, the page and the charts, on 127.0.0.1 with its own data; and
Debian's headless Chromium driven by Playwright."""

import re
from pathlib import Path

import pytest

from tests.server.api.conftest import serve, settings_for

CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = Path(__file__).parent / "artifacts"
# Playwright cannot download its own browser here: Debian's chromium, quiet and sandbox-free
# (the tests may run as root in a container, where Chromium's sandbox cannot start).
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


@pytest.fixture
def served(tmp_path):
    yield from serve(settings_for(tmp_path))


@pytest.fixture
def page():
    if not CHROMIUM.exists():
        pytest.skip("no /usr/bin/chromium (.ci/run installs it)")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=ARGS)
        context = browser.new_context(viewport={"width": 1200, "height": 900})
        page = context.new_page()
        page.set_default_timeout(60_000)
        yield page
        context.close()
        browser.close()


def sign_in(page, served) -> None:
    """Open the page, give it the token, and wait for the cells it then lists (data-loaded: the
    page's own default option is there before them)."""
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")


def shot(page, name: str) -> Path:
    """A full-page screenshot under tests/web/artifacts; its path."""
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


# What a notice for people must not say: HTTP verbs, API paths, status codes and phrases (the
# request and its status are under "details", for an engineer).
HTTP_WORDS = re.compile(
    r"\b(GET|POST|PUT|PATCH|DELETE)\b|/api/|\b(400|401|403|404|409|413|422|429|500|502|503)\b"
    r"|Unprocessable|Unauthorized|Forbidden|Internal Server Error"
)


def said(page) -> tuple[str, str]:
    """The message row's words and its details (the request and status); the words checked free
    of HTTP."""
    text = page.text_content("#message-text") or ""
    technical = page.text_content("#message-technical") or ""
    assert not HTTP_WORDS.search(text), f"the message speaks HTTP: {text!r}"
    return text, technical
