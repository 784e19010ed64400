"""What the study server refuses before a route sees the request (an ASGI middleware, outside the app's routes):

- a ``Host`` header other than the address the server was started on (DNS rebinding: a page on another site whose
  name resolves to 127.0.0.1 would otherwise read and write the study): 400;
- a request body over :data:`MAX_BODY_BYTES` (a vote or a rater name is under 200 bytes), from ``Content-Length``
  and while reading a body sent without one: 413, the rest never read into memory;
- a JSON body that is not strict JSON: ``NaN``, ``Infinity`` and numbers that overflow a float (``1e400``) are no
  JSON, and FastAPI's own parser takes them, then fails to write them back in its 422 (a 500): 422 here.

Every refusal is a JSON ``{"detail": ...}`` as the app's own errors.
"""

from __future__ import annotations

import json
import math

from starlette.responses import JSONResponse

from aias_augment.core.errors import AiasError

MAX_BODY_BYTES = 64 * 1024
_BODY_METHODS = frozenset({"POST", "PUT", "PATCH"})


class _TooLarge(AiasError):
    pass


def _finite_float(text: str) -> float:
    v = float(text)
    if not math.isfinite(v):
        raise ValueError(f"number {text[:32]} overflows a float")
    return v


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def strict_json_problem(body: bytes) -> str | None:
    """Why ``body`` is not strict JSON (NaN, Infinity, an overflowing number, bad syntax), or None."""
    try:
        json.loads(body, parse_constant=_no_constant, parse_float=_finite_float)
    except RecursionError:
        return "JSON nested too deeply"
    except ValueError as e:  # json.JSONDecodeError, UnicodeDecodeError, and the refusals above
        return f"not valid JSON: {e}"
    return None


def host_names(host: str, port: int) -> frozenset[str]:
    """The ``Host`` headers a server bound to ``host``:``port`` answers: that address and the loopback names, with
    the port (lower case; an IPv6 address in brackets). Bound to every interface (``0.0.0.0``, ``::``), raters on
    other machines reach it by this machine's names and addresses: those too."""
    names = {host, "localhost", "127.0.0.1", "::1"}
    if host in ("", "0.0.0.0", "::"):
        import socket

        hostname = socket.gethostname()
        names |= {hostname, socket.getfqdn()}
        try:
            names |= {info[4][0] for info in socket.getaddrinfo(hostname, None)}
        except OSError:  # a host name that does not resolve: its names only
            pass
    return frozenset(f"[{n}]:{port}".lower() if ":" in n else f"{n}:{port}".lower() for n in names if n)


class RequestGuard:
    """ASGI middleware: the refusals of the module docstring. ``allowed_hosts`` is read from the app's state at each
    request (``app.state.allowed_hosts``, set once the port is bound); None accepts any Host."""

    def __init__(self, app, state, max_body_bytes: int = MAX_BODY_BYTES):
        self.app, self.state, self.max_body_bytes = app, state, max_body_bytes

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        allowed = getattr(self.state, "allowed_hosts", None)
        if allowed is not None and headers.get("host", "").strip().lower() not in allowed:
            host = headers.get("host", "")[:80]
            return await self._refuse(scope, receive, send, 400, f"this server does not answer for host {host!r}")
        if scope["method"] not in _BODY_METHODS:
            return await self.app(scope, receive, send)
        length = headers.get("content-length")
        if length is not None and (not length.strip().isdigit() or int(length) > self.max_body_bytes):
            return await self._refuse(scope, receive, send, 413, f"request body over {self.max_body_bytes} bytes")
        try:
            body = await self._read_body(receive)
        except _TooLarge:
            return await self._refuse(scope, receive, send, 413, f"request body over {self.max_body_bytes} bytes")
        if body and "json" in headers.get("content-type", ""):
            problem = strict_json_problem(body)
            if problem:
                return await self._refuse(scope, receive, send, 422, problem)
        return await self.app(scope, _replay(body, receive), send)

    async def _read_body(self, receive) -> bytes:
        chunks, size = [], 0
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                break
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_body_bytes:
                raise _TooLarge
            chunks.append(chunk)
            if not message.get("more_body", False):
                break
        return b"".join(chunks)

    @staticmethod
    async def _refuse(scope, receive, send, status: int, detail: str):
        headers = {"Connection": "close"} if status == 413 else None  # the unread rest of the body ends the connection
        await JSONResponse({"detail": detail}, status_code=status, headers=headers)(scope, receive, send)


def _replay(body: bytes, receive):
    """``receive`` for the app: the body read by the guard, then the connection's own messages (its disconnect)."""
    sent = False

    async def replay():
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay
