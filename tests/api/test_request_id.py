"""X-Request-Id: accepted when well-formed, generated otherwise, echoed, in problems and logs."""

from __future__ import annotations

import logging
import re

import pytest

from service.log import RequestIdFilter
from tests.api.helpers import assert_problem


def test_given_request_id_is_echoed(client):
    response = client.get("/healthz", headers={"X-Request-Id": "trace-42.a_b"})
    assert response.headers["x-request-id"] == "trace-42.a_b"


def test_request_id_is_generated_when_absent(client):
    first = client.get("/healthz").headers["x-request-id"]
    second = client.get("/healthz").headers["x-request-id"]
    assert re.fullmatch(r"[0-9a-f]{32}", first)
    assert first != second


@pytest.mark.parametrize("bad", ["has space", "x" * 129, "semi;colon", "ünïcode", ""])
def test_malformed_request_id_is_replaced(client, bad):
    response = client.get("/healthz", headers={"X-Request-Id": bad.encode("utf-8")})
    assert re.fullmatch(r"[0-9a-f]{32}", response.headers["x-request-id"])


def test_request_id_is_in_problem_bodies(client):
    response = client.get("/missing", headers={"X-Request-Id": "abc"})
    assert assert_problem(response, 404)["request_id"] == "abc"
    assert response.headers["x-request-id"] == "abc"


def test_request_id_is_in_log_lines(client, caplog):
    caplog.handler.addFilter(RequestIdFilter())
    with caplog.at_level(logging.INFO, logger="service"):
        client.get("/healthz", headers={"X-Request-Id": "log-me"})
    access = [r for r in caplog.records if r.name == "service.access"]
    assert access and access[-1].request_id == "log-me"
    assert "/healthz 200" in access[-1].getMessage()
