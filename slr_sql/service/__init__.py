"""The network service (docs/service.md): one knowledge base over HTTP/JSON and WebSocket.

* :mod:`slr_sql.service.app` — ``create_app(kb)``, the Starlette application;
* :mod:`slr_sql.service.client` — ``connect(url)``, also ``slr_sql.connect``;
* :mod:`slr_sql.service.encoding` — the JSON encoding of terms, both ways;
* :mod:`slr_sql.service.errors` — errors as JSON, and back;
* :mod:`slr_sql.service.cli` — ``slr serve``.

This package sits above the knowledge base and uses only its public API; nothing below it
imports it. Importing it imports nothing from starlette, uvicorn or httpx (the modules that
need them import them).
"""
