"""schemathesis against the live service: every operation's documented statuses, content types
and schemas hold for generated requests (valid and invalid ones), with the token."""

from __future__ import annotations

import time

import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis.core.failures import Failure, FailureGroup
from schemathesis.generation import GenerationMode
from schemathesis.specs.openapi import checks

from .conftest import serve, settings_for

# They command motion on the (simulated) cell: a run would move the arm for every generated
# case that names an existing campaign, and make the test long; their refusals (401, 404, 409,
# 422) are the same code paths as the other campaign actions', which are tested here.
MOTION = {
    ("POST", "/api/campaigns/{campaign_id}/start"),
    ("POST", "/api/campaigns/{campaign_id}/resume"),
}
# An endless text/event-stream: a client that reads the whole body (as schemathesis does)
# would wait forever; test_event_stream_is_documented_and_guarded checks it instead.
STREAMS = {("GET", "/api/events")}
# Their body is a whole file (cell.json, meas.csv) whose validity goes beyond any schema (joints
# within the robot's limits, an orthonormal base, one row per pose and target): a schema-valid
# body is mostly a bad file, refused 422 with its line. Every other check still runs on them.
FILES = {
    ("POST", "/api/cells"),
    ("POST", "/api/measurements/import"),
    ("POST", "/api/models/{job_id}/compensate"),
    ("POST", "/api/models/{job_id}/export"),
    ("POST", "/api/models/{job_id}/checks"),
}
# A plan's size is bounded by the product poses x choose_from (said in the field's description),
# which no JSON Schema can state: a schema-valid plan beyond it is refused 422 naming both
# fields (test_bounds_api's oversized plans). Every other check still runs on it.
PRODUCT_BOUNDED = {("POST", "/api/campaigns")}
FILE_CHECKS_EXCLUDED = [checks.positive_data_acceptance]
# Examples per operation and generation mode: bounded so the whole run stays near a minute.
EXAMPLES = {GenerationMode.POSITIVE: 20, GenerationMode.NEGATIVE: 10}


@pytest.fixture
def live_schema(tmp_path):
    for live in serve(settings_for(tmp_path)):
        auth = {"Authorization": f"Bearer {live.token}"}
        schema = schemathesis.openapi.from_url(f"{live.url}/openapi.json", headers=auth)
        # An undeclared query parameter is ignored, as HTTP services do; schemathesis 4.32 counts
        # accepting it as a failure (its issue 3730), so negative cases mutate declared data only.
        schema.config.generation.update(allow_extra_parameters=False)
        yield live, schema, auth


def test_schemathesis_finds_no_failure(live_schema):
    live, schema, auth = live_schema
    cases, failures, seen_ops = 0, [], 0
    started = time.monotonic()
    for result in schema.get_all_operations():
        op = result.ok()
        if (op.method.upper(), op.path) in MOTION | STREAMS:
            continue
        seen_ops += 1
        for mode, n in EXAMPLES.items():
            found = []
            key = (op.method.upper(), op.path)
            excluded = FILE_CHECKS_EXCLUDED if key in FILES | PRODUCT_BOUNDED else []

            @settings(
                max_examples=n,
                derandomize=True,
                database=None,
                deadline=None,
                phases=[Phase.explicit, Phase.generate],
                suppress_health_check=list(HealthCheck),
            )
            @given(case=op.as_strategy(generation_mode=mode))
            def run(case):
                nonlocal cases
                cases += 1
                response = case.call(base_url=live.url, headers=auth, timeout=30)
                try:
                    case.validate_response(response, headers=auth, excluded_checks=excluded)  # noqa: B023 (run() is called in this iteration)
                except (Failure, FailureGroup) as e:
                    errors = getattr(e, "exceptions", [e])
                    found.append(  # noqa: B023
                        f"{op.method.upper()} {op.path} [{mode.value}]: "  # noqa: B023
                        f"{'; '.join(sorted({x.title for x in errors}))}: "
                        f"{response.status_code} {response.text[:300]!r} "
                        f"(query {case.query}, body {str(case.body)[:200]!r})"
                    )

            t0 = time.monotonic()
            try:
                run()
            except Unsatisfiable:
                # No parameters and no body (GET /api/health): nothing can be made invalid.
                assert mode is GenerationMode.NEGATIVE
                continue
            failures.extend(found)
            print(
                f"{op.method.upper()} {op.path} [{mode.value}]: {len(found)} failures, "
                f"{time.monotonic() - t0:.1f} s",
                flush=True,
            )
    elapsed = time.monotonic() - started
    unique = sorted(set(failures))
    print(
        f"\nschemathesis: {seen_ops} operations, {cases} cases, {len(failures)} failures "
        f"({len(unique)} distinct) in {elapsed:.1f} s"
    )
    for f in unique:
        print(" ", f)
    assert seen_ops >= 25
    assert not failures
