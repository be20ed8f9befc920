"""`slr serve` against its own OpenAPI description: hypothesis generates requests for every
operation the description lists (bodies that follow the schema, bodies that break it, wrong
methods), sends them to a real server process, and checks what comes back: a status the
description lists for that operation, a JSON error body of the documented shape, `Allow` on
a 405, never a 5xx, the server up. Plus the malformed-body case of the HTTP layer."""
from __future__ import annotations

import re
import socket
import time

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from service_helpers import HTTP, ServiceProcess

TOKEN = "s3cret"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("schema") / "schema.db"
    with ServiceProcess(db, "--token", TOKEN, "--max-query-time", "0.5",
                        "--max-wait", "0.5") as s:
        with httpx.Client(base_url=s.url, headers=AUTH) as c:
            c.post("/load", json={"text": "p(1). p(2). q(X) :- p(X)."})
            c.post("/add", json={"event": "seen(a)^1"})
        yield s


@pytest.fixture(scope="module")
def spec(server):
    return HTTP.get(server.url + "/openapi.json").json()


def _resolve(schema: dict, spec: dict) -> dict:
    while "$ref" in schema:
        schema = spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
    return schema


# -- values that follow a (sub)schema of the description ---------------------------------------

_SLR_TEXTS = st.sampled_from(["p(X)", "q(X)", "seen(W)^T", "p(1)^2", "true", "fail", "X = 1",
                              "p(", "seen(a)^[1, 2]", "p/1", "main", "", "SELECT 1",
                              "p(_)", "findall(X, p(X), L)", "1 is 1", "seen/1"])


def _value(schema: dict, spec: dict, depth: int = 0) -> st.SearchStrategy:
    schema = _resolve(schema, spec)
    if "anyOf" in schema:
        return st.one_of([_value(s, spec, depth + 1) for s in schema["anyOf"]])
    if "enum" in schema:
        return st.sampled_from(schema["enum"])
    kind = schema.get("type")
    if isinstance(kind, list):
        return st.one_of([_value({"type": k}, spec, depth + 1) for k in kind])
    if kind == "string":
        return st.one_of(_SLR_TEXTS, st.text(max_size=12))
    if kind == "integer":
        return st.integers(-3, 10**6)
    if kind == "number":
        return st.one_of(st.integers(-5, 100), st.floats(-1e3, 1e13, allow_nan=False))
    if kind == "boolean":
        return st.booleans()
    if kind == "null":
        return st.none()
    if kind == "array" or depth > 3:
        items = schema.get("items", {"type": "string"})
        return st.lists(_value(items, spec, depth + 1) if depth <= 3 else st.integers(),
                        min_size=schema.get("minItems", 0), max_size=schema.get("maxItems", 3))
    if kind == "object":
        props = schema.get("properties", {})
        required = schema.get("required", [])
        if not props:
            extra = schema.get("additionalProperties", {"type": "string"})
            return st.dictionaries(st.sampled_from(["X", "Y", "T"]),
                                   _value(extra, spec, depth + 1), max_size=2)
        return st.fixed_dictionaries(
            {k: _value(props[k], spec, depth + 1) for k in required},
            optional={k: _value(v, spec, depth + 1) for k, v in props.items()
                      if k not in required})
    return st.one_of(st.integers(), st.text(max_size=5), st.none())   # a Term


_ANY_JSON = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(), st.floats(
    allow_nan=False, allow_infinity=False), st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8)


WEBSOCKETS = ("/subscribe", "/solutions")     # (the paths of WebSockets: not HTTP)


def _operations(spec: dict) -> list[tuple[str, str, dict]]:
    return [(path, method.upper(), op) for path, ops in spec["paths"].items()
            for method, op in ops.items() if path not in WEBSOCKETS]


@st.composite
def _request(draw, spec: dict) -> tuple:
    path, method, op = draw(st.sampled_from(_operations(spec)))
    url = path
    for name in re.findall(r"\{(\w+)\}", path):
        param = next(p for p in op["parameters"] if p["name"] == name)
        value = draw(st.integers(0, 5) if param["schema"]["type"] == "integer"
                     else st.text(alphabet="abcdef0123456789", min_size=1, max_size=32))
        url = url.replace("{" + name + "}", str(value))
    params = {}
    for param in op.get("parameters", []):
        if param["in"] == "query" and (param["required"] or draw(st.booleans())):
            params[param["name"]] = draw(st.one_of(st.sampled_from(["p/1", "seen/1", "0", "-1",
                                                                    "x"]), st.text(max_size=5)))
    body = None
    if "requestBody" in op:
        schema = op["requestBody"]["content"]["application/json"]["schema"]
        body = draw(st.one_of(_value(schema, spec), _ANY_JSON))   # valid, or anything
    wrong_method = draw(st.booleans()) and draw(st.integers(0, 4)) == 0
    if wrong_method:
        taken = {m.upper() for m in spec["paths"][path]} | {"HEAD"}
        method = draw(st.sampled_from(sorted({"GET", "POST", "PUT", "DELETE", "PATCH"} - taken)))
    auth = draw(st.integers(0, 9)) > 0
    return path, method, url, params, body, wrong_method, auth, op


def test_every_answer_is_one_the_description_lists(server, spec):
    statuses_seen: set = set()
    operations_seen: set = set()

    @settings(max_examples=250, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(request=_request(spec))
    def check(request):
        path, method, url, params, body, wrong_method, auth, op = request
        kwargs = {"params": params, "headers": AUTH if auth else {}}
        if body is not None:
            kwargs["json"] = body
        response = HTTP.request(method, server.url + url, timeout=30, **kwargs)
        status = response.status_code
        statuses_seen.add(status)
        operations_seen.add((path, method))
        assert status < 500, (method, url, body, response.text)
        if wrong_method:
            assert status == 405, (method, url, status)
            allowed = {m.strip() for m in response.headers["allow"].split(",")}
            assert {m.upper() for m in spec["paths"][path]} <= allowed
        elif status == 404 and "{" not in path:
            raise AssertionError(f"404 on a listed path: {method} {url}")
        else:
            assert str(status) in op["responses"], (method, url, status, response.text)
            if op.get("security") != [] and not auth:
                assert status == 401
        if status >= 400:
            error = response.json()["error"]
            assert {"kind", "status", "message"} <= set(error) and error["status"] == status
            assert "internal error" not in error["message"]

    check()
    assert len(operations_seen) >= len(_operations(spec)) * 0.8, operations_seen
    assert {200, 400, 401, 405} <= statuses_seen, statuses_seen
    assert server.healthy()
    log = server.log.read_text()
    assert "Traceback" not in log and "internal error" not in log, log[-3000:]


def test_the_description_lists_the_statuses_of_its_operations(spec):
    ops = {(path, method): op["responses"] for path, method, op in _operations(spec)}
    assert {"200", "400", "401", "408", "413", "503"} <= set(ops[("/query", "POST")])
    assert {"200", "202", "404", "408"} <= set(ops[("/submit/{handle}", "GET")])
    assert {"200", "404"} <= set(ops[("/buffers/{buffer_id}", "DELETE")])
    assert "401" not in ops[("/health", "GET")]
    # a robot's token (--robot-tokens) beyond shipping as its robot
    assert "403" in ops[("/query", "POST")] and "403" in ops[("/fleet/receive", "POST")]
    programs = ops[("/programs", "GET")]["200"]["content"]["application/json"]["schema"]
    assert programs["properties"]["programs"] == {"$ref": "#/components/schemas/ProgramMap"}


# -- the HTTP layer: a body the server cannot parse ---------------------------------------------

MALFORMED = [
    # a chunk size that is not hexadecimal, no token
    b"POST /add HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n"
    b"Content-Type: application/json\r\n\r\nzz\r\nabc\r\n0\r\n\r\n",
    # a chunk shorter than its size, with the token
    b"POST /add HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n"
    b"Authorization: Bearer " + TOKEN.encode() + b"\r\n\r\n5\r\nabc\r\n0\r\n\r\n",
    # the same on another endpoint, no token
    b"POST /query HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n"
    b"3\r\nabcdef\r\n0\r\n\r\n",
]


def _send_raw(url: str, data: bytes) -> bytes:
    host, port = url.rsplit("//", 1)[1].rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=10) as s:
        s.sendall(data)
        received = b""
        while True:
            chunk = s.recv(4096)
            if not chunk:
                return received
            received += chunk


def test_a_malformed_chunked_body_gets_a_clean_400_and_one_log_line(tmp_path):
    rounds = 4
    with ServiceProcess(tmp_path / "chunked.db", "--token", TOKEN) as server:
        for _ in range(rounds):
            for data in MALFORMED:
                answer = _send_raw(server.url, data)
                assert answer.startswith(b"HTTP/1.1 400 "), answer
        assert server.healthy()
        # every request above was answered and its connection closed; the log is written by
        # the server before it closes: a request after them finds every line there
        assert HTTP.post(server.url + "/query", json={"goal": "true"},
                         headers=AUTH).json() == {"answers": [{}]}
        deadline = time.monotonic() + 10
        while server.log.read_text().count("Invalid HTTP request") < rounds * len(MALFORMED):
            assert time.monotonic() < deadline, server.log.read_text()
            time.sleep(0.05)
    lines = [line for line in server.log.read_text().splitlines() if line.strip()]
    assert len(lines) == rounds * len(MALFORMED), lines
    assert all("Invalid HTTP request received." in line for line in lines), lines


def test_each_operation_without_parameters_goes_straight_to_its_endpoint(spec):
    """The routes without path parameters are served without starlette's routing (the app
    looks the exact method and path up): the table holds every such operation of the
    description (HEAD with GET) and only those, each to the endpoint the router picks."""
    import slr_sql
    from starlette.routing import Match
    from slr_sql.service.app import _direct_routes, create_app

    with slr_sql.open() as kb:
        app = create_app(kb)
        direct = _direct_routes(app.routes)
    expected = set()
    for path, ops in spec["paths"].items():
        if "{" not in path and path not in WEBSOCKETS:
            expected |= {(m.upper(), path) for m in ops}
            expected |= {("HEAD", path)} if "get" in ops else set()
    assert set(direct) == expected and ("POST", "/add_many") in direct
    for (method, path), endpoint in direct.items():
        scope = {"type": "http", "path": path, "root_path": "", "method": method}
        assert next(r for r in app.routes
                    if r.matches(scope)[0] is Match.FULL).endpoint is endpoint
