"""/docs works without the internet: Swagger UI's page, JavaScript and CSS come from the service
itself (the swagger-ui-bundle-v2 package), and the page renders with every other host cut off."""

import re
from urllib.parse import urlparse


def test_docs_and_their_assets_come_from_the_service(served):
    c = served.anonymous  # the documents need no token, as before
    r = c.get("/docs")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    assert not re.search(r"https?://|//cdn", html), "an external URL in /docs"
    urls = re.findall(r"""(?:src|href)=["']([^"']+)["']""", html)
    assert {"/docs/assets/swagger-ui-bundle.js", "/docs/assets/swagger-ui.css"} <= set(urls)
    for url in urls:
        assert not urlparse(url).netloc, url
        asset = c.get(url)
        assert asset.status_code == 200, url
    js = c.get("/docs/assets/swagger-ui-bundle.js")
    assert "javascript" in js.headers["content-type"] and len(js.content) > 500_000
    assert "text/css" in c.get("/docs/assets/swagger-ui.css").headers["content-type"]
    assert c.get("/openapi.json").json()["info"]["title"] == "robocal"
    assert c.get("/redoc").status_code == 404  # ReDoc would be a CDN page: not offered


def test_docs_render_with_the_internet_cut_off(served, page):
    outside = []

    def only_this_service(route):
        host = urlparse(route.request.url).hostname
        if host in ("127.0.0.1", "localhost"):
            route.continue_()
        else:
            outside.append(route.request.url)
            route.abort()

    page.route("**/*", only_this_service)
    page.goto(f"{served.url}/docs")
    page.wait_for_selector(".swagger-ui .info .title")
    assert "robocal" in page.inner_text(".swagger-ui .info .title")
    page.wait_for_selector(".opblock-tag")  # the operations, grouped by tag
    assert page.locator(".opblock").count() > 20
    assert not outside, outside
