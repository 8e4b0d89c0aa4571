"""What keeps a live session to its own browser: origins, connection limits, slow clients, binding.

- **Origins.** A browser sends `Origin` with every websocket handshake and every cross-origin (and
  same-origin) POST. The server accepts only its own addresses (`own_origins`: the bound host and
  port, the loopback names for a loopback or wildcard bind, the machine's addresses for a wildcard
  bind) and the public addresses it is told it is reached at behind a proxy (`--public-origin`).
  A request without `Origin` comes from no browser page (a script, the scripted participant) and
  still needs its token.
- **Hosts.** Every request and websocket handshake must be addressed (its `Host`) to one of those
  origins, or it is refused (421) before anything else is looked at: a page of another site whose
  name is made to resolve to this machine (DNS rebinding) sends that site's name, and so reads
  not even the pages that need no token.
- **Connections per participant.** `ConnectionGate`: at most MAX_SOCKETS open websockets per
  participant (the live one and the one replacing it) and new connections at most OPEN_BURST at
  once, then OPEN_RATE a second (a token bucket per participant).
- **Request bodies.** `RequestGuard` (ASGI middleware before every route): a state-changing
  request needs one of our origins (or none) and a Content-Length; a request framed by
  Transfer-Encoding is refused (a chunked body has no length to check before it is read); the
  body actually received is counted, reading stopped and the request refused (413) as soon as it
  passes MAX_BODY_BYTES, whatever the headers said; a JSON body naming a key twice (or nested too
  deeply to parse) is refused (422), as websocket messages are. The body is parsed there once: the
  routes (`GuardedRoute`) validate the value the guard parsed.
- **Connections in all.** At most `connection_cap` connections are open at once (HTTP and
  websocket; sized for the study: CONNECTIONS_PER_PARTICIPANT for each planned participant and
  CONNECTIONS_SPARE, never more than half the process's open-file limit): one beyond is answered
  503 and closed as it is accepted, so clients that open connections and send nothing cannot use
  up the server's file descriptors. Should accept() still fail for want of descriptors, asyncio's
  traceback per attempt becomes one warning (`GuardedServer`).
- **Connections per address.** At most CONNECTIONS_PER_ADDRESS of those from one address (two
  stations' browsers' worth), answered as beyond the cap in all: one machine holding idle sockets
  cannot take every slot. Loopback is not capped by default: the machine's own clients (the
  console, scripts) and a reverse proxy in front of the server, for which every client is one
  address, share the cap in all (`ServerOptions.connections_per_address` caps every address).
- **Quiet refusals.** A refusal costs its client one response and the server no log line beyond
  uvicorn's one warning for a request it cannot parse: the answer to a request whose framing broke
  after its headers (h11 has answered 400 and is closing the connection) is dropped, not sent on
  the closing connection (`GuardedH11Protocol.send_400_response`), and a websocket handshake
  refused by an HTTP response (ASGI's denial response: the 421 of a foreign Host) counts as a
  completed handshake (`GuardedWebSocketProtocol`).
- **Slow clients.** `GuardedH11Protocol` closes an HTTP connection whose request (headers and
  body, or a websocket handshake) is not complete within `request_seconds` of its first byte or
  of the connection (idle, slow headers, slow body: uvicorn has a keep-alive timeout only between
  requests). An open websocket that sends nothing for `idle_seconds` is closed by the application
  (harness/live/app.py); the station pings every 20 s.
- **Binding.** `bind` takes the port before anything is printed or written: a port in use is an
  InputError (one line, exit code 2) and leaves nothing behind.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import resource
import socket
from collections.abc import Mapping
from urllib.parse import urlsplit

import h11
import uvicorn
from fastapi.routing import APIRoute
from starlette.datastructures import Headers, MutableHeaders
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send
from uvicorn.protocols.http.h11_impl import H11Protocol
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from trustroute.core import defaults
from trustroute.core.errors import InputError
from trustroute.harness.live.protocol import (
    MAX_BODY_BYTES,
    MessageError,
    TokenBucket,
    error_reply,
    json_value,
)

MAX_SOCKETS = 2        # open websockets per participant: the live one and the one replacing it
OPEN_BURST = 5         # new websockets a participant may open at once ...
OPEN_RATE = 0.5        # ... and per second after that
CONNECTIONS_PER_PARTICIPANT = defaults.LIVE_CONNECTIONS_PER_BROWSER   # one browser's, a station's
CONNECTIONS_SPARE = 32            # the experimenter's console, scripts, connections being closed
CONNECTIONS_PER_ADDRESS = 2 * CONNECTIONS_PER_PARTICIPANT   # from one address other than loopback
FULL_TEXT = b"too many open connections; try again later"
FULL = (b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nConnection: close\r\n"
        b"Content-Length: %d\r\n\r\n%s" % (len(FULL_TEXT), FULL_TEXT))
WILDCARDS = ("0.0.0.0", "::", "")
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
STATE_CHANGING = ("POST", "PUT", "PATCH", "DELETE")
# Every response: no framing, no sniffing, no referrer (a participant link carries a token), and
# scripts, styles and sockets from this server only.
SECURITY_HEADERS = {"X-Content-Type-Options": "nosniff", "X-Frame-Options": "DENY",
                    "Referrer-Policy": "no-referrer", "Cache-Control": "no-store",
                    "Content-Security-Policy": "default-src 'self'; connect-src 'self'; "
                                               "img-src 'self' data:; frame-ancestors 'none'"}
PARSED_BODY = "trustroute.parsed_body"   # the scope key of a body's JSON, as RequestGuard parsed it


def is_loopback(host: str) -> bool:
    """Whether `host` names this machine's loopback (an IPv4 one mapped into IPv6, as a dual-stack
    bind sees an IPv4 peer, too)."""
    if host == "localhost":
        return True
    try:
        address = ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        return False
    mapped = address.ipv4_mapped if isinstance(address, ipaddress.IPv6Address) else None
    return (mapped or address).is_loopback


def shown_host(host: str) -> str:
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


def usable_addresses(host: str) -> list[str]:
    """The addresses a browser can reach a server bound to `host` at: the host itself, or for a
    wildcard the machine's own addresses (loopback last)."""
    if host not in WILDCARDS:
        return [host]
    family = socket.AF_INET6 if host == "::" else socket.AF_INET
    found: list[str] = []
    for name in (socket.gethostname(), socket.getfqdn()):
        try:
            infos = socket.getaddrinfo(name, None, family, socket.SOCK_STREAM)
        except OSError:
            continue
        for info in infos:
            address = str(info[4][0])
            if not is_loopback(address) and address not in found:
                found.append(address)
    return [*found, "::1" if family == socket.AF_INET6 else "127.0.0.1"]


def normal_origin(origin: str) -> str | None:
    """scheme://host[:port] in lower case, the default port left out; None when it is no origin."""
    try:
        parts = urlsplit(origin.strip())
        port = parts.port
    except ValueError:
        return None
    if parts.scheme not in ("http", "https") or not parts.hostname:
        return None
    default = 443 if parts.scheme == "https" else 80
    port_text = "" if port in (None, default) else f":{port}"
    return f"{parts.scheme}://{shown_host(parts.hostname.lower())}{port_text}"


def own_origins(host: str, port: int, public: tuple[str, ...] = ()) -> frozenset[str]:
    """The origins of the server's own pages: every usable address of the bind, the loopback
    names when it is reachable on loopback, and the configured public origins."""
    hosts = set(usable_addresses(host))
    if is_loopback(host) or host in WILDCARDS:
        hosts.update(LOOPBACK_NAMES)
    origins = {normal_origin(f"http://{shown_host(name)}:{port}") for name in hosts}
    origins.update(normal_origin(origin) for origin in public)
    return frozenset(origin for origin in origins if origin is not None)


def addressed_origins(host: str) -> frozenset[str]:
    """The origins a request's `Host` names (over http and https); none for a Host that is no
    bare host[:port] (empty, or with a user, path, query or fragment)."""
    if not host or any(mark in host for mark in "@/\\?# "):
        return frozenset()
    addressed = (normal_origin(f"http://{host}"), normal_origin(f"https://{host}"))
    return frozenset(origin for origin in addressed if origin)


def origin_allowed(headers: Mapping[str, str], origins: frozenset[str] | None) -> bool:
    """Whether a request may act: no Origin (no browser page sent it), or one of ours; with no
    origins configured (an application embedded without `serve`), the origin the request was
    addressed to (its Host)."""
    origin = headers.get("origin")
    if origin is None:
        return True
    if origins is None:
        origins = addressed_origins(headers.get("host", ""))
    return normal_origin(origin) in origins


def host_allowed(headers: Mapping[str, str], origins: frozenset[str] | None) -> bool:
    """Whether a request was addressed (its Host) to one of our origins (the module's "Hosts");
    with no origins configured (an application embedded without `serve`), to any."""
    return origins is None or not addressed_origins(headers.get("host", "")).isdisjoint(origins)


class ConnectionGate:
    """Per participant: open websockets and the rate of new ones (the event loop's thread only)."""

    def __init__(self, max_sockets: int = MAX_SOCKETS, burst: float = OPEN_BURST,
                 rate: float = OPEN_RATE) -> None:
        self.max_sockets, self.burst, self.rate = max_sockets, burst, rate
        self.open: dict[int, int] = {}
        self.buckets: dict[int, TokenBucket] = {}

    def admit(self, participant: int) -> bool:
        """Whether one more websocket of `participant` may open now (counted if so)."""
        bucket = self.buckets.setdefault(participant, TokenBucket(burst=self.burst, rate=self.rate))
        if self.open.get(participant, 0) >= self.max_sockets or not bucket.take():
            return False
        self.open[participant] = self.open.get(participant, 0) + 1
        return True

    def release(self, participant: int) -> None:
        self.open[participant] = max(0, self.open.get(participant, 0) - 1)


class RequestGuard:
    """ASGI middleware before every route: the Host of every request and websocket handshake
    (the module's "Hosts"), then an HTTP request's headers and body ("Request bodies"); the
    origins are the application's `state.origins` (None: any Host, and the origin each request
    was addressed to)."""

    def __init__(self, app: ASGIApp, limit: int = MAX_BODY_BYTES) -> None:
        self.app, self.limit = app, limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        origins = scope["app"].state.origins
        if not host_allowed(Headers(scope=scope), origins):
            await misdirected(Headers(scope=scope).get("host", ""))(scope, receive, secured(send))
        elif scope["type"] == "websocket":
            await self.app(scope, receive, send)
        else:
            await self.guarded(scope, receive, secured(send), origins)

    async def guarded(self, scope: Scope, receive: Receive, send: Send,
                      origins: frozenset[str] | None) -> None:
        """An HTTP request addressed to us: its headers and body checked, then the application."""
        refusal = request_refusal(scope["method"], Headers(scope=scope), origins, self.limit)
        if refusal is None:
            received = await read_body(receive, self.limit)
            if received is None:
                refusal = oversized(self.limit)
            else:
                refusal = parse_body(received, scope)
                if refusal is None:
                    await self.app(scope, replayed(received, receive), send)
                    return
        await refusal(scope, receive, send)


def secured(send: Send) -> Send:
    """`send` with SECURITY_HEADERS on every response (a websocket handshake's refusal too)."""

    async def sending(message: Message) -> None:
        if message["type"] in ("http.response.start", "websocket.http.response.start"):
            MutableHeaders(scope=message).update(SECURITY_HEADERS)
        await send(message)

    return sending


def misdirected(host: str) -> JSONResponse:
    """421 for a request (or websocket handshake) addressed to a host that is none of ours."""
    detail = (f"this server is not reached as {host[:80]!r}: open it at the address it printed "
              "(behind a proxy: --public-origin names the address it is reached at)")
    return refused(421, {"detail": error_reply("forbidden", detail)})


def refused(status: int, content: dict) -> JSONResponse:
    """A refusal; it ends the connection (the body it leaves unread is never read)."""
    return JSONResponse(content, status, headers={"Connection": "close"})


def request_refusal(method: str, headers: Headers, origins: frozenset[str] | None,
                    limit: int) -> JSONResponse | None:
    """The refusal a request's method and headers call for before its body is read, or None."""
    length = headers.get("content-length", "")
    if "transfer-encoding" in headers:
        framed = "a body needs a Content-Length, not a Transfer-Encoding"
        return refused(411, {"type": "error", "detail": framed})
    if method in STATE_CHANGING and not origin_allowed(headers, origins):
        return refused(403, {"detail": error_reply("forbidden", "a request from another site's page")})
    if method in STATE_CHANGING and not length.isdigit():
        return refused(411, {"type": "error", "detail": "a body needs a Content-Length"})
    if length.isdigit() and int(length) > limit:
        return oversized(limit)
    return None


def parse_body(received: list[Message], scope: Scope) -> JSONResponse | None:
    """422 `malformed` for a JSON body that names a key twice or is nested too deeply to parse
    (protocol.json_value, the websocket's reader too), else None, the parsed value kept as
    scope[PARSED_BODY] for the route (a body that is no JSON keeps its ValueError there: the
    route's to refuse, if it reads a body)."""
    body = b"".join(message.get("body", b"") for message in received)
    try:
        scope[PARSED_BODY] = json_value(body, "body")
    except MessageError as exc:
        return refused(422, exc.reply)
    except ValueError as exc:
        scope[PARSED_BODY] = exc
    return None


class ParsedRequest(Request):
    """A request whose JSON is the value RequestGuard parsed (FastAPI reads a body model's JSON
    with `json()`): a body is parsed once."""

    async def json(self) -> object:
        parsed = self.scope[PARSED_BODY]
        if isinstance(parsed, ValueError):
            raise parsed
        return parsed


class GuardedRoute(APIRoute):
    """A route behind RequestGuard: it validates the body the guard parsed (`ParsedRequest`)."""

    def get_route_handler(self):
        handler = super().get_route_handler()

        async def parsed(request: Request) -> Response:
            return await handler(ParsedRequest(request.scope, request.receive))

        return parsed


def oversized(limit: int) -> JSONResponse:
    return refused(413, error_reply("oversized", f"bodies hold at most {limit} bytes"))


async def read_body(receive: Receive, limit: int) -> list[Message] | None:
    """The request's messages from the ASGI channel up to its body's end (or the client's
    disconnect); None as soon as the body received passes `limit` bytes (nothing more is read)."""
    received: list[Message] = []
    size = 0
    while True:
        message = await receive()
        received.append(message)
        size += len(message.get("body", b""))
        if size > limit:
            return None
        if message["type"] != "http.request" or not message.get("more_body", False):
            return received


def replayed(received: list[Message], receive: Receive) -> Receive:
    """A receive channel giving `received` first, then the connection's own (its disconnect)."""
    pending = list(received)

    async def replay() -> Message:
        return pending.pop(0) if pending else await receive()

    return replay


def connection_cap(participants: int) -> int:
    """The open connections a study's server allows at once (the module's "Connections in all")."""
    files = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    wanted = participants * CONNECTIONS_PER_PARTICIPANT + CONNECTIONS_SPARE
    return wanted if files == resource.RLIM_INFINITY else max(1, min(wanted, files // 2))


def address_cap(host: str, per_address: int | None) -> int | None:
    """The open connections one peer address may hold (the module's "Connections per address"):
    `per_address` if given, else CONNECTIONS_PER_ADDRESS, loopback uncapped (None)."""
    if per_address is not None:
        return per_address
    return None if is_loopback(host) else CONNECTIONS_PER_ADDRESS


class GuardedH11Protocol(H11Protocol):
    """uvicorn's HTTP/1.1 protocol with caps on open connections and a deadline on every
    request: a connection beyond `max_connections`, or beyond its address's cap (`address_cap` of
    `per_address`), is answered 503 and closed at once; one that has not sent a whole request
    (headers and body) within `request_seconds` of being opened, or of its previous response, is
    closed (a websocket upgrade leaves this protocol, and the deadline with it; it stays counted).
    Set them on a subclass (`guarded_protocol`)."""

    request_seconds = 10.0
    max_connections = 1 << 30
    per_address: int | None = None

    request_deadline: asyncio.TimerHandle | None = None

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        self.request_deadline = None
        if len(self.connections) > self.max_connections or self.crowded():   # (this one counted)
            transport.write(FULL)
            transport.close()
            return
        self.arm()

    def crowded(self) -> bool:
        """Whether this connection's address holds more open connections (HTTP and websocket,
        this one counted) than its cap."""
        if not self.client:
            return False
        host = self.client[0]
        cap = address_cap(host, self.per_address)
        if cap is None:
            return False
        peers = [each.client for each in self.connections   # (the protocols this server speaks)
                 if isinstance(each, (H11Protocol, WebSocketsSansIOProtocol))]
        return sum(peer is not None and peer[0] == host for peer in peers) > cap

    def send_400_response(self, msg: str) -> None:
        """uvicorn's 400 for a request it cannot parse, which closes the connection; a request
        whose framing broke after its headers is with the application already: its answer is
        dropped (uvicorn would send it on the closing connection, fail, and log a traceback)."""
        super().send_400_response(msg)
        if self.cycle is not None:
            self.cycle.disconnected = True
            self.cycle.message_event.set()   # a body being read ends (http.disconnect)

    def arm(self) -> None:
        self.disarm()
        self.request_deadline = self.loop.call_later(self.request_seconds, self.too_slow)

    def disarm(self) -> None:
        if self.request_deadline is not None:
            self.request_deadline.cancel()
            self.request_deadline = None

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        if self.request_complete() or self.transport.get_protocol() is not self:
            self.disarm()

    def request_complete(self) -> bool:
        return self.conn.their_state in (h11.DONE, h11.MUST_CLOSE, h11.CLOSED, h11.SWITCHED_PROTOCOL)

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self.arm()

    def connection_lost(self, exc: Exception | None) -> None:
        self.disarm()
        super().connection_lost(exc)

    def too_slow(self) -> None:
        self.request_deadline = None
        transport = self.transport
        if transport.is_closing() or transport.get_protocol() is not self or self.request_complete():
            return
        transport.close()


def guarded_protocol(request_seconds: float, max_connections: int,
                     per_address: int | None = None) -> type[GuardedH11Protocol]:
    return type("GuardedH11", (GuardedH11Protocol,), {"request_seconds": float(request_seconds),
                                                      "max_connections": int(max_connections),
                                                      "per_address": per_address})


class GuardedWebSocketProtocol(WebSocketsSansIOProtocol):
    """uvicorn's websocket protocol (the one it picks with `websockets` installed), whose
    handshake refused by an HTTP response (ASGI's websocket denial response) counts as completed:
    else uvicorn logs "ASGI callable returned without completing handshake" for each."""

    async def send(self, message: Message) -> None:  # type: ignore[override]
        await super().send(message)  # type: ignore[arg-type]
        if message["type"] == "websocket.http.response.body" and not message.get("more_body", False):
            self.handshake_complete = True


class GuardedServer(uvicorn.Server):
    """uvicorn's server whose event loop says a failed accept() (out of file descriptors; asyncio
    tries again a second later) once, as one warning line, instead of a traceback each time."""

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        quiet_accept_errors(asyncio.get_running_loop())
        await super().startup(sockets)


def quiet_accept_errors(loop: asyncio.AbstractEventLoop) -> None:
    said = False

    def handler(loop: asyncio.AbstractEventLoop, context: dict) -> None:
        nonlocal said
        if not str(context.get("message", "")).startswith("socket.accept() out of system resource"):
            loop.default_exception_handler(context)
        elif not said:
            said = True
            logging.getLogger("uvicorn.error").warning(
                "the server is out of file descriptors (%s): new connections wait until some close "
                "(said once)", context.get("exception"))

    loop.set_exception_handler(handler)


def bind(host: str, port: int) -> socket.socket:
    """A listening socket on (host, port); InputError when it cannot be had (in use, no such
    address), before anything of the study is printed or written. The socket names its protocol
    (TCP): asyncio turns Nagle's algorithm off (TCP_NODELAY) only on accepted connections whose
    protocol is TCP, and with it on, a mode event written behind a frame waits for the station's
    delayed acknowledgement of that frame (40 ms on Linux)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if family == socket.AF_INET6:
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 0)
        sock.bind((host, port))
        sock.listen(128)
    except OSError as exc:
        sock.close()
        raise InputError("--port", f"{shown_host(host)}:{port}", f"cannot listen there ({exc.strerror})",
                         "choose another --port (or stop what holds it), or another --host") from None
    sock.set_inheritable(False)
    return sock
