"""Who may use the live page: the served address, the page's origin, and a per-run token.

The page shows the camera and writes into ``--out``, so no other web site the user has open may
reach it. Every request passes three checks (an aiohttp middleware, :func:`guard_middleware`):

* **Host** (against DNS rebinding, where a stranger's domain is made to resolve to 127.0.0.1): the
  ``Host`` header must name the served address: ``127.0.0.1:PORT``, ``localhost:PORT``,
  ``[::1]:PORT``, the ``--host`` given, or the address the connection came in on (with
  ``--host 0.0.0.0``, the machine's address on the network), or the machine's name when serving
  other machines. PORT is the port the connection came in on.
* **Origin** (against cross-site requests and websocket hijacking): any request that carries an
  ``Origin`` (a browser sends one with every websocket, every POST and every cross-site fetch)
  must come from ``http://`` one of those addresses. A client that is not a browser sends none; it still needs
  the token.
* **Token** (as Jupyter's): ``/ws``, ``/state``, ``/config`` and ``/save`` need ``?token=`` (or an
  ``X-Aicalib-Token`` header) equal to the run's random token, which is only in the address the
  server prints at start (:func:`new_token`). The page reads it from its own address and passes
  it on.

A refused request gets 403 and one line of text saying which check failed; the console shows the
first :data:`MAX_LOGGED` refusals, one line each.
"""

from __future__ import annotations

import hmac
import secrets
import socket
import sys
from urllib.parse import urlsplit

__all__ = ["new_token", "guard_middleware", "refusal", "PROTECTED", "MAX_LOGGED"]

PROTECTED = ("/ws", "/state", "/config", "/save")  # the routes that need the token
MAX_LOGGED = 20  # refusals printed on the console; later ones are only counted
_LOOPBACK = ("127.0.0.1", "localhost", "[::1]")
_ANY = ("0.0.0.0", "::", "[::]", "")


def new_token() -> str:
    """A fresh random token for one run (URL-safe text, 192 bits)."""
    return secrets.token_urlsafe(24)


def _bracket(host: str) -> str:
    """An IPv6 address in the brackets a Host header or URL writes it in; other names lower-cased."""
    host = host.strip().lower()
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


def _split_host(text: str, default_port: int) -> tuple[str, int] | None:
    """``"localhost:8765"`` / ``"[::1]:8765"`` / ``"example"`` -> (host, port); None when malformed."""
    text = text.strip().lower()
    if text.startswith("["):
        end = text.find("]")
        if end < 0:
            return None
        host, rest = text[:end + 1], text[end + 1:]
        port = rest[1:] if rest.startswith(":") else ("" if not rest else None)
    else:
        host, _, port = text.partition(":")
    if port is None or (port and not port.isdigit()) or not host:
        return None
    return host, int(port) if port else default_port


def _allowed_hosts(bind_host: str, local_ip: str) -> set[str]:
    hosts = {*_LOOPBACK, _bracket(local_ip)}
    if _bracket(bind_host) in _ANY:
        hosts.add(socket.gethostname().lower())
    else:
        hosts.add(_bracket(bind_host))
    return hosts - {""}


def refusal(path: str, headers, query, *, token: str, bind_host: str, local: tuple) -> str | None:
    """Why a request is refused (one line), or None when it may go on.

    headers, query : mappings (case-insensitive headers); local : (ip, port) the connection came in on.
    """
    ip, port = local[0], int(local[1])
    allowed = _allowed_hosts(bind_host, str(ip))
    host = _split_host(headers.get("Host", ""), 80)
    if host is None or host[0] not in allowed or host[1] != port:
        return f"Host {headers.get('Host', '(none)')!r} is not this server's address"
    origin = headers.get("Origin")
    if origin is not None:
        parts = urlsplit(origin)
        where = _split_host(parts.netloc, 80) if parts.scheme == "http" and not parts.path.strip("/") else None
        if where is None or where[0] not in allowed or where[1] != port:
            return f"Origin {origin!r} is not this page"
    if path in PROTECTED:
        given = query.get("token") or headers.get("X-Aicalib-Token") or ""
        if not hmac.compare_digest(given.encode(), token.encode()):
            return "missing or wrong token (open the address the server printed)"
    return None


def guard_middleware(token: str, bind_host: str):
    """An aiohttp middleware refusing (403) what :func:`refusal` refuses, for a server bound to ``bind_host``."""
    from aiohttp import web

    logged = [0]

    @web.middleware
    async def guard(request, handler):
        sock = request.transport.get_extra_info("sockname") if request.transport is not None else None
        local = (sock[0], sock[1]) if sock else ("", -1)
        why = refusal(request.path, request.headers, request.query, token=token, bind_host=bind_host, local=local)
        if why is None:
            return await handler(request)
        logged[0] += 1
        if logged[0] <= MAX_LOGGED:
            print(f"refused {request.method} {request.path}: {why}", file=sys.stderr, flush=True)
        return web.Response(status=403, text=f"refused: {why}\n")

    return guard
