"""`slr serve --ssl-keyfile K --ssl-certfile C` end to end: a real server process with a
certificate of a test CA (trustme), and clients that trust that CA or do not.

A client trusts the CAs of ``$SSL_CERT_FILE`` and ``$SSL_CERT_DIR`` (else certifi's bundle),
for its requests (httpx) and its subscriptions (websockets) alike: one TLS context per client
(docs/service.md, TLS).
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import trustme
from service_helpers import ServiceProcess, slr_env

import slr_sql
from slr_sql import Atom, SLRError
from slr_sql.service.errors import ServiceError


@pytest.fixture(scope="module")
def tls(tmp_path_factory) -> dict[str, Path]:
    """A test CA and a certificate it signed for 127.0.0.1, as PEM files."""
    folder = tmp_path_factory.mktemp("tls")
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1")
    files = {name: folder / f"{name}.pem" for name in ("ca", "key", "cert", "other_ca")}
    ca.cert_pem.write_to_path(str(files["ca"]))
    cert.private_key_pem.write_to_path(str(files["key"]))
    for i, pem in enumerate(cert.cert_chain_pems):
        pem.write_to_path(str(files["cert"]), append=i > 0)
    trustme.CA().cert_pem.write_to_path(str(files["other_ca"]))   # a CA that signed nothing
    return files


@pytest.fixture(scope="module")
def server(tmp_path_factory, tls):
    db = tmp_path_factory.mktemp("tls_db") / "s.db"
    with ServiceProcess(db, "--ssl-keyfile", str(tls["key"]),
                        "--ssl-certfile", str(tls["cert"])) as s:
        assert s.url.startswith("https://127.0.0.1:")
        yield s


@pytest.fixture
def trusting(monkeypatch, tls):
    monkeypatch.setenv("SSL_CERT_FILE", str(tls["ca"]))
    monkeypatch.delenv("SSL_CERT_DIR", raising=False)


@pytest.fixture
def not_trusting(monkeypatch):
    """Neither variable: certifi's bundle, which has no test CA."""
    monkeypatch.delenv("SSL_CERT_FILE", raising=False)
    monkeypatch.delenv("SSL_CERT_DIR", raising=False)


def _query_add_subscribe(url: str, tag: str) -> None:
    with slr_sql.connect(url) as kb:
        assert kb.query("X = 1") == [{"X": 1}]
        kb.add(f"{tag}(a)^1")
        assert kb.query(f"{tag}(X)^T") == [{"X": Atom("a"), "T": 1.0}]
        with kb.subscribe(f"{tag}(X)^T", since=0) as sub:     # wss://
            assert sub.get(timeout=10)["X"] == Atom("a")
            # the requests' context: on its own, websockets trusts the system's CAs
            assert sub._ws.socket.context is kb._tls


def test_a_client_trusting_the_ca_queries_adds_and_subscribes_over_tls(server, trusting):
    _query_add_subscribe(server.url, "seen")


def test_ssl_cert_dir_is_trusted_by_requests_and_subscriptions_alike(server, tls, tmp_path,
                                                                    monkeypatch):
    """The CA in $SSL_CERT_DIR while $SSL_CERT_FILE names another bundle (one a Python
    distribution sets, say): both are trusted, as OpenSSL does (httpx on its own read only
    the file, the subscriptions' websockets both)."""
    openssl = shutil.which("openssl")
    # (the openssl command names the CA's file by its subject hash: missing, the test fails
    # rather than being skipped -- a test environment without it checks less than CI's)
    assert openssl is not None, "no openssl command to name the CA's file by its subject hash"
    folder = tmp_path / "certs"
    folder.mkdir()
    shutil.copy(tls["ca"], folder / "test-ca.pem")
    subprocess.run([openssl, "rehash", str(folder)], check=True, capture_output=True,
                   timeout=30)
    monkeypatch.setenv("SSL_CERT_DIR", str(folder))
    monkeypatch.setenv("SSL_CERT_FILE", str(tls["other_ca"]))
    _query_add_subscribe(server.url, "dir_seen")


def _assert_not_trusted(exc: BaseException, url: str) -> None:
    assert isinstance(exc, ServiceError), repr(exc)
    assert exc.kind != "Unavailable" and exc.status == 0     # no retry makes it pass
    assert url in str(exc) and "not trusted" in str(exc) and "SSL_CERT_FILE" in str(exc)
    assert exc.__cause__ is None and exc.__suppress_context__


def test_a_client_not_trusting_the_certificate_gets_an_slr_error_saying_so(server,
                                                                        not_trusting):
    with slr_sql.connect(server.url) as kb:
        with pytest.raises(SLRError) as caught:
            kb.query("X = 1")
        _assert_not_trusted(caught.value, server.url)
        with pytest.raises(SLRError) as caught:
            kb.subscribe("seen(X)^T", since=0)
        _assert_not_trusted(caught.value, server.url)


def test_a_certificate_for_another_host_is_not_trusted_either(server, trusting):
    url = server.url.replace("127.0.0.1", "localhost")       # the certificate is for the IP
    with slr_sql.connect(url) as kb, pytest.raises(ServiceError) as caught:
        kb.query("X = 1")
    assert caught.value.kind == "CertificateNotTrusted" and caught.value.status == 0
    assert url in str(caught.value) and "not trusted" in str(caught.value)
    assert "names another host" in str(caught.value)


def test_the_cli_says_the_certificate_is_not_trusted(server):
    env = slr_env()
    env.pop("SSL_CERT_FILE", None)
    env.pop("SSL_CERT_DIR", None)
    done = subprocess.run([sys.executable, "-m", "slr_sql", "query", server.url, "X = 1"],
                          capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode != 0
    assert done.stderr.startswith("error: ") and done.stderr.count("\n") == 1, done.stderr
    assert "not trusted" in done.stderr and server.url in done.stderr
    assert "Traceback" not in done.stderr and "bug" not in done.stderr


def test_an_unreadable_ssl_cert_file_is_an_slr_error_naming_it(tmp_path, monkeypatch):
    missing = tmp_path / "no-such-ca.pem"
    monkeypatch.setenv("SSL_CERT_FILE", str(missing))
    monkeypatch.delenv("SSL_CERT_DIR", raising=False)
    with pytest.raises(SLRError, match="SSL_CERT_FILE") as caught:
        slr_sql.connect("https://127.0.0.1:1")
    assert str(missing) in str(caught.value)
    with slr_sql.connect("http://127.0.0.1:1"):     # plain HTTP reads no CA
        pass


@pytest.mark.parametrize("given", ["--ssl-keyfile", "--ssl-certfile"])
def test_slr_serve_refuses_one_tls_file_without_the_other(tmp_path, tls, given):
    path = tls["key"] if given == "--ssl-keyfile" else tls["cert"]
    done = subprocess.run([sys.executable, "-m", "slr_sql", "serve", str(tmp_path / "t.db"),
                           "--port", "0", given, str(path)],
                          capture_output=True, text=True, env=slr_env(), timeout=60,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 1
    assert done.stderr == "error: TLS needs both --ssl-keyfile and --ssl-certfile\n"
    assert done.stdout == ""
