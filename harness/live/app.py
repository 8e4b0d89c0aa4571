"""The live study's web application (FastAPI): HTTP API, participant websocket, links.

Every route checks who is asking (harness/live/auth.py) before it reads anything; before that,
every request and websocket handshake is checked for its Host, and every state-changing request
and websocket handshake for its Origin (harness/live/guard.py):

    GET  /login?token=T                the console link: T (one-time) is exchanged for a fresh
                                       session token in the HttpOnly cookie, then to /console
    POST /api/login-link               experimenter: a new one-time console link
    GET  /p/{token}                    a participant's link: a page that claims the token (below)
    POST /api/claim {"token": T}       the link's page: T is replaced by a fresh token in the
                                       cookie (the link in the browser's history is spent)
    GET  /console, /station            the pages (experimenter; participant), plain HTML and JS
    GET  /static/{name}                their scripts and style sheet
    GET  /favicon.ico                  the site's icon (browsers ask for it by themselves)
    GET  /api/me                       participant: their own progress and the consent text
    GET  /api/net                      participant or experimenter: the net's lanes (the view)
    POST /api/participants             experimenter: create the next participant -> link
    GET  /api/participants             experimenter: every participant's progress
    GET  /api/participants/{p}         experimenter, or participant p themself
    POST /api/participants/{p}/control experimenter: pause, resume or abort p's episode
    POST /api/participants/{p}/link    experimenter: a new link for p (the old token revoked; one
                                       who declined is asked for their consent again)
    POST /api/participants/{p}/withdraw experimenter: p's data deleted (harness/live/withdraw.py);
                                       the packages exported before that still hold p named
    GET  /api/files                    experimenter: the study directory's files
    GET  /api/download/{path}          experimenter: one file, inside the study directory only
    WS   /ws                           participant: the protocol of harness/live/protocol.py

Request bodies are capped (MAX_BODY_BYTES, counted as received), parsed once (a key given twice
refused: guard.py) and validated (protocol.py models); every refusal is a JSON error of the
protocol's form with an HTTP status, and changes nothing. A browser holds one role: a console
login is refused where a participant's session cookie is held, a link's claim where the console's
is (`holds_role`). A participant has one live websocket:
a second one replaces the first (both are told); a socket silent for `idle_seconds` is closed.
`serve` runs the application on uvicorn on a socket bound beforehand (websocket frames capped at
the transport too, slow requests cut: guard.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from html import escape
from pathlib import Path

from fastapi import APIRouter, Depends, FastAPI, HTTPException, Request, WebSocket, WebSocketDisconnect
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse
from starlette.requests import HTTPConnection

from trustroute.harness.live.auth import (
    CONSOLE_IDLE_SECONDS,
    EXPERIMENTER_COOKIE,
    PARTICIPANT_COOKIE,
    presented_token,
    token_digest,
    well_formed,
)
from trustroute.harness.live.guard import (
    ConnectionGate,
    GuardedRoute,
    GuardedServer,
    GuardedWebSocketProtocol,
    RequestGuard,
    connection_cap,
    guarded_protocol,
    normal_origin,
    origin_allowed,
    own_origins,
)
from trustroute.harness.live.protocol import (
    CONTROL_RATE,
    MAX_MESSAGE_BYTES,
    SHOWN_RATE,
    EpisodeControl,
    LinkClaim,
    MessageError,
    NewParticipant,
    TokenBucket,
    Withdrawal,
    error_reply,
    parse_client_message,
)
from trustroute.harness.live.server import LiveStudy
from trustroute.harness.live.session import Session
from trustroute.harness.live.withdraw import withdrawal_line

PAGES = Path(__file__).with_name("pages")
# The driver's view renders with three.js, shipped in pages/vendor/ with its licence (pinned:
# docs/live_studies.md), so no page loads a script from elsewhere.
STATIC = {"live.css": "text/css", "console.js": "text/javascript", "station.js": "text/javascript",
          "driver_view.js": "text/javascript", "map_view.js": "text/javascript",
          "inputs.js": "text/javascript", "link.js": "text/javascript", "questionnaire.js": "text/javascript",
          "next_turn.js": "text/javascript",
          "vendor/three.module.js": "text/javascript", "vendor/three.core.js": "text/javascript"}
OUTBOX = 1024          # messages queued for one websocket; frames are dropped first
FRAMES_UP_TO = OUTBOX // 2
POLICY_VIOLATION = 1008  # websocket close codes: no valid participant token, or a foreign Origin;
TRY_AGAIN_LATER = 1013   # too many connections of this participant;
REPLACED = 4001          # another window of the participant took the session over;
IDLE = 4408              # nothing received for idle_seconds
CLOSE = "close"          # the outbox's last item: close the socket with (code, reason)


class Link:
    """One participant websocket's outbox, pushed to from any thread (the episode's reader);
    `digest`: the digest of the token the socket was opened with."""

    def __init__(self, loop: asyncio.AbstractEventLoop, digest: str) -> None:
        self.loop, self.digest = loop, digest
        self.queue: asyncio.Queue = asyncio.Queue(maxsize=OUTBOX)
        self.closed = False   # set by `shut` at once: nothing the socket sends after it is acted on

    def __call__(self, message: dict) -> None:
        self.loop.call_soon_threadsafe(offer, self.queue, message)

    def shut(self, code: int, reason: str, last: dict | None = None) -> None:
        """Close the socket with `code` after `last` (what is still queued is dropped)."""
        self.closed = True
        self.loop.call_soon_threadsafe(self._shut, code, reason, last)

    def _shut(self, code: int, reason: str, last: dict | None) -> None:
        while not self.queue.empty():
            self.queue.get_nowait()
        if last is not None:
            self.queue.put_nowait(last)
        self.queue.put_nowait((CLOSE, code, reason))


class OpenSockets:
    """Every open participant websocket's Link, by participant (from any thread)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.links: dict[int, set[Link]] = {}

    def add(self, participant: int, link: Link) -> None:
        with self.lock:
            self.links.setdefault(participant, set()).add(link)

    def discard(self, participant: int, link: Link) -> None:
        with self.lock:
            self.links.get(participant, set()).discard(link)

    def of(self, participant: int) -> list[Link]:
        with self.lock:
            return list(self.links.get(participant, ()))


def revoke_stale(connection: HTTPConnection, participant: int, reason: str = "revoked",
                 detail: str = "this link was revoked") -> None:
    """Close every open websocket of `participant` opened with a token that is no longer theirs
    (replaced by a claimed link or a new one, or gone with a withdrawal): told `revoked`, code 1008."""
    current = study_of(connection).credentials.participants.get(participant)
    for link in connection.app.state.sockets.of(participant):
        if link.digest != current:
            link.shut(POLICY_VIOLATION, reason, {"type": "revoked", "detail": detail})


def offer(queue: asyncio.Queue, message: dict) -> None:
    """Queue a message for the socket; a frame is dropped when the socket is behind."""
    if message.get("type") == "frame" and queue.qsize() >= FRAMES_UP_TO:
        return
    with contextlib.suppress(asyncio.QueueFull):
        queue.put_nowait(message)


def respond(session: Session, bucket: TokenBucket, data: str | bytes,
            controls: TokenBucket | None = None, shown: TokenBucket | None = None) -> list[dict]:
    """The replies to one raw client message (an error reply for a refused one). A wheel's
    `control` messages count against `controls`, the station's `shown` against `shown`, every
    other message against `bucket`."""
    try:
        message = parse_client_message(data)
    except MessageError as exc:
        return [exc.reply] if bucket.take() else [error_reply("rate_limited", "too many messages; slow down")]
    stream = {"control": controls, "shown": shown}.get(message.type)
    if not (stream if stream is not None else bucket).take():
        return [error_reply("rate_limited", "too many messages; slow down")]
    try:
        return session.handle(message)
    except MessageError as exc:
        return [exc.reply]


def refused(status: int, code: str, detail: str) -> HTTPException:
    return HTTPException(status, error_reply(code, detail))


def cookie_redirect(request: Request, target: str, cookie: str, token: str) -> RedirectResponse:
    """Set the token's cookie (HttpOnly, SameSite=Strict; Secure when the study is served over
    HTTPS, --secure-cookies) and send the browser on without the token in its address bar."""
    response = RedirectResponse(target, status_code=303)
    response.set_cookie(cookie, token, httponly=True, samesite="strict", path="/",
                        secure=study_of(request).options.secure_cookies)
    return response


router = APIRouter(route_class=GuardedRoute)   # (the body RequestGuard parsed is the one validated)


def study_of(connection: HTTPConnection) -> LiveStudy:
    return connection.app.state.study


def holds_role(request: Request, cookie: str) -> bool:
    """Whether the request's browser holds a valid token in `cookie` (the experimenter's or a
    participant's: a console login and a link's claim are refused where the other role's is)."""
    token = presented_token({}, request.cookies, cookie)
    credentials = study_of(request).credentials
    if cookie == EXPERIMENTER_COOKIE:
        return credentials.is_experimenter(token)
    return credentials.participant_of(token) is not None


def experimenter(request: Request) -> None:
    """Dependency: the request carries the experimenter's token (401 without a token, 403 with another)."""
    token = presented_token(request.headers, request.cookies, EXPERIMENTER_COOKIE)
    credentials = study_of(request).credentials
    if credentials.console_expired(token):
        raise refused(401, "forbidden", CONSOLE_EXPIRED)
    if not credentials.is_experimenter(token):
        raise refused(401 if token is None else 403, "forbidden", "the experimenter's token is needed")


def participant_token(request: Request) -> int:
    """Dependency: the participant the request's token names (403 for any other token)."""
    token = presented_token(request.headers, request.cookies, PARTICIPANT_COOKIE)
    found = study_of(request).credentials.participant_of(token)
    if found is None:
        raise refused(403, "forbidden", "a participant link is needed")
    return found


def session_of(request: Request, participant: int) -> Session:
    session = study_of(request).sessions.get(participant)
    if session is None:
        raise refused(404, "not_found", f"no participant {participant}")
    return session


async def malformed(request: Request, exc: Exception) -> JSONResponse:
    errors = exc.errors() if isinstance(exc, RequestValidationError) else []
    first = errors[0] if errors else {}
    where = ".".join(str(part) for part in first.get("loc", ()))
    return JSONResponse(error_reply("malformed", f"{where}: {first.get('msg', 'invalid')}"), 422)


# What a browser opening a page it may not see is told (refused_page), by page.
CONSOLE_TITLE, STATION_TITLE = "trustroute live: experimenter console", "Driving study"
MAKE_CONSOLE_LINK = ("make one with the experimenter token (POST /api/login-link; "
                     "docs/live_studies.md, Running a session).")
NEW_CONSOLE_LINK = "open the new console link the server printed when it started, or " + MAKE_CONSOLE_LINK
UNUSED = f"unused for {CONSOLE_IDLE_SECONDS // 3600} hours"
CONSOLE_EXPIRED = (f"This console login has expired ({UNUSED}): log in again from a console link; "
                   + MAKE_CONSOLE_LINK)
CONSOLE_REFUSED = ("This browser is not logged in to the console: the server was restarted, the login "
                   f"expired ({UNUSED}), or it is gone. To go on, " + NEW_CONSOLE_LINK)
LOGIN_REFUSED = "This console link is spent or unknown. To log in, " + NEW_CONSOLE_LINK
# A browser holds one role: whoever sits at a browser holding both cookies could open the console.
CONSOLE_HERE = ("This browser is logged in to the experimenter console, where a participant could open it: "
                "open the participant's link in another browser (or a private window).")
STATION_HERE = ("A participant's session is open in this browser, where they could open the console: open "
                "the console link in another browser (or a private window).")
STATION_REFUSED = ("This session is not open in this browser. Open the link the experimenter gave you, or "
                   "ask the experimenter for a new one. If you have withdrawn from the study, your data "
                   "has been deleted; if you did not agree to take part, none was recorded: you can close "
                   "this window.")


def refused_page(request: Request, refusal: HTTPException, title: str, text: str) -> HTMLResponse:
    """A page refused to a browser (its request accepts text/html: a navigation) is a readable page
    saying what to do, with the refusal's status; any other client gets the JSON refusal."""
    if "text/html" not in request.headers.get("accept", ""):
        raise refusal
    page = (PAGES / "refused.html").read_text()
    page = page.replace("{title}", escape(title)).replace("{text}", escape(text))
    return HTMLResponse(page, refusal.status_code)


@router.get("/login", response_model=None)
def login(request: Request, token: str = "") -> RedirectResponse | HTMLResponse:
    """The console link: its one-time token is exchanged for a fresh session token, which only the
    cookie holds (the link left in the browser's history, or a proxy's log, is spent)."""
    if holds_role(request, PARTICIPANT_COOKIE):   # (the link is not spent: it works in another browser)
        refusal = refused(409, "out_of_order", STATION_HERE)
        return refused_page(request, refusal, CONSOLE_TITLE, STATION_HERE)
    session = study_of(request).login(well_formed(token))
    if session is None:
        refusal = refused(403, "forbidden", "this login link is spent or unknown; ask the server for a new "
                                            "one (POST /api/login-link with the experimenter token)")
        return refused_page(request, refusal, CONSOLE_TITLE, LOGIN_REFUSED)
    return cookie_redirect(request, "/console", EXPERIMENTER_COOKIE, session)


@router.post("/api/login-link", dependencies=[Depends(experimenter)])
def login_link(request: Request) -> dict:
    """A new one-time console link (the experimenter token never goes into an address)."""
    return {"link": f"/login?token={study_of(request).new_login_link()}"}


@router.get("/p/{token}")
def participant_link(token: str) -> FileResponse:
    """The link's page: its script claims the token from the address (POST /api/claim) and goes on
    to /station. Nothing changes on a GET, so a link preview spends no link."""
    return FileResponse(PAGES / "link.html", media_type="text/html")


@router.post("/api/claim")
def claim(request: Request, body: LinkClaim) -> JSONResponse:
    """The token of a link opened in a browser is replaced by a fresh one, which only the cookie
    holds: the link left in the browser's history is spent (403 when opened again)."""
    study = study_of(request)
    if holds_role(request, EXPERIMENTER_COOKIE):   # (the link is not spent: it works in another browser)
        raise refused(409, "out_of_order", CONSOLE_HERE)
    try:
        participant, token = study.claim_link(body.token)
    except ValueError as exc:
        raise refused(403, "forbidden", str(exc)) from None
    revoke_stale(request, participant)   # a socket opened with the link's token acts no more
    response = JSONResponse({"next": "/station"})
    response.set_cookie(PARTICIPANT_COOKIE, token, httponly=True, samesite="strict", path="/",
                        secure=study.options.secure_cookies)
    return response


def guarded_page(request: Request, admit: Callable[[Request], object], page: str, title: str,
                 refused: str) -> FileResponse | HTMLResponse:
    """A page for whom `admit` lets in; to anyone else the refusal as a readable page (JSON for
    clients that are not browsers)."""
    try:
        admit(request)
    except HTTPException as refusal:
        return refused_page(request, refusal, title, refused)
    return FileResponse(PAGES / page, media_type="text/html")


@router.get("/console", response_model=None)
def console(request: Request) -> FileResponse | HTMLResponse:
    return guarded_page(request, experimenter, "console.html", CONSOLE_TITLE, CONSOLE_REFUSED)


@router.get("/station", response_model=None)
def station(request: Request) -> FileResponse | HTMLResponse:
    return guarded_page(request, participant_token, "station.html", STATION_TITLE, STATION_REFUSED)


@router.get("/favicon.ico")
def favicon() -> FileResponse:
    """The site's icon, which a browser asks for by itself on every page (a missing one is a 404
    in the browser's console); the pages name none, so this address is the one."""
    return FileResponse(PAGES / "favicon.svg", media_type="image/svg+xml")


@router.get("/static/{name:path}")
def static(name: str) -> FileResponse:
    if name not in STATIC:
        raise refused(404, "not_found", "no such file")
    return FileResponse(PAGES / name, media_type=STATIC[name])


@router.get("/api/me")
def me(request: Request, participant: int = Depends(participant_token)) -> dict:
    return {**session_of(request, participant).progress(), "consent": study_of(request).consent_text}


@router.get("/api/net")
def net(request: Request) -> dict:
    """The net's lanes: for the participants' stations and the experimenter."""
    token = presented_token(request.headers, request.cookies, EXPERIMENTER_COOKIE)
    if not study_of(request).credentials.is_experimenter(token):
        participant_token(request)
    return study_of(request).net_view()


@router.post("/api/participants", dependencies=[Depends(experimenter)])
def create_participant(request: Request, body: NewParticipant) -> dict:
    try:
        participant, token = study_of(request).create_participant(body.label)
    except ValueError as exc:
        raise refused(409, "out_of_order", str(exc)) from None
    return {"participant": participant, "token": token, "link": f"/p/{token}"}


@router.get("/api/participants", dependencies=[Depends(experimenter)])
def participants(request: Request) -> dict:
    return {"participants": [s.progress() for _, s in sorted(study_of(request).sessions.items())]}


@router.get("/api/participants/{participant}")
def participant_progress(request: Request, participant: int) -> dict:
    token = presented_token(request.headers, request.cookies, EXPERIMENTER_COOKIE)
    if not study_of(request).credentials.is_experimenter(token) and participant_token(request) != participant:
        raise refused(403, "forbidden", "a participant sees only their own session")
    return session_of(request, participant).progress()


@router.post("/api/participants/{participant}/control", dependencies=[Depends(experimenter)])
def control(request: Request, participant: int, body: EpisodeControl) -> dict:
    try:
        return session_of(request, participant).control(body.action)
    except MessageError as exc:
        raise HTTPException(409, exc.reply) from None


@router.post("/api/participants/{participant}/link", dependencies=[Depends(experimenter)])
def new_link(request: Request, participant: int) -> dict:
    """A new link for `participant`: a fresh token; the old one (link or cookie) is revoked and
    their open websocket closed. The server keeps only digests, so a link is shown once."""
    study = study_of(request)
    if session_of(request, participant).phase == "declined":
        study.ask_again(participant)
    try:
        token = study.replace_token(participant, "new link issued by the experimenter")
    except ValueError as exc:   # (they have withdrawn)
        raise refused(409, "out_of_order", str(exc)) from None
    revoke_stale(request, participant)
    return {"participant": participant, "token": token, "link": f"/p/{token}"}


@router.post("/api/participants/{participant}/withdraw", dependencies=[Depends(experimenter)])
def withdraw(request: Request, participant: int, body: Withdrawal) -> dict:
    """Withdraw `participant`: their data deleted, the dataset consolidated without them, the
    deletion audited (harness/live/withdraw.py); their open station closed. The answer names the
    packages exported before that still hold them (the audit's `exported`) and carries the line
    `trustroute withdraw` prints, which the console shows."""
    study = study_of(request)
    session_of(request, participant)
    try:
        entry = study.withdraw(participant, body.reason)
    except ValueError as exc:
        raise refused(409, "out_of_order", str(exc)) from None
    revoke_stale(request, participant, "withdrawn", "withdrawn from the study")
    return {"participant": participant, "removed": len(entry["removed"]), "utc": entry["utc"],
            "exported": entry.get("exported", []), "line": withdrawal_line(study.study_dir, entry)}


@router.get("/api/files", dependencies=[Depends(experimenter)])
def files(request: Request) -> dict:
    return {"files": study_of(request).files()}


@router.get("/api/download/{path:path}", dependencies=[Depends(experimenter)])
def download(request: Request, path: str) -> FileResponse:
    try:
        target = study_of(request).download_path(path)
    except ValueError as exc:
        raise refused(404, "not_found", str(exc)) from None
    return FileResponse(target, filename=target.name)


@router.websocket("/ws")
async def station_socket(websocket: WebSocket) -> None:
    """A participant's socket: their token, one of our origins, and room under their limit."""
    study = study_of(websocket)
    token = presented_token(websocket.headers, websocket.cookies, PARTICIPANT_COOKIE)
    participant = study.credentials.participant_of(token)
    foreign = not origin_allowed(websocket.headers, websocket.app.state.origins)
    if token is None or participant is None or foreign:
        await websocket.close(code=POLICY_VIOLATION)
        return
    gate: ConnectionGate = websocket.app.state.gate
    if not gate.admit(participant):
        await websocket.close(code=TRY_AGAIN_LATER)
        return
    link, sockets = Link(asyncio.get_running_loop(), token_digest(token)), websocket.app.state.sockets
    sockets.add(participant, link)
    revoke_stale(websocket, participant)   # (its token replaced since it was checked above)
    try:
        await websocket.accept()
        await converse(websocket, study.sessions[participant], link, study.consent_text,
                       study.options.idle_seconds)
    finally:
        sockets.discard(participant, link)
        gate.release(participant)


def live_app(study: LiveStudy, origins: frozenset[str] = frozenset()) -> FastAPI:
    """The application serving `study` (opened: credentials and directory lock held); `origins`:
    the server's own (guard.own_origins), beside the study's configured public ones, which a
    request's Host must name; with neither, any Host is served and a request's Origin must be the
    address it was sent to (its Host)."""
    app = FastAPI(title="trustroute live", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.study = study
    public = {normal_origin(origin) for origin in study.options.public_origins}
    configured = frozenset(origins) | {origin for origin in public if origin is not None}
    app.state.origins = configured or None   # none: the origin each request was addressed to
    app.state.gate = ConnectionGate()
    app.state.sockets = OpenSockets()
    app.add_middleware(RequestGuard)
    app.add_exception_handler(RequestValidationError, malformed)
    app.include_router(router)
    return app


async def converse(websocket: WebSocket, session: Session, link: Link, consent_text: str,
                   idle_seconds: float) -> None:
    """One participant connection: replies and the episode's messages out, client messages in.
    It replaces the participant's previous connection (which is told and closed), unless it is
    closed already (revoked)."""

    async def send_all() -> None:
        while True:
            message = await link.queue.get()
            if isinstance(message, tuple):
                await websocket.close(code=message[1], reason=message[2])
                return
            await websocket.send_json(message)

    sender = asyncio.create_task(send_all())
    buckets = (TokenBucket(), TokenBucket(burst=CONTROL_RATE, rate=CONTROL_RATE),
               TokenBucket(burst=SHOWN_RATE, rate=SHOWN_RATE))
    offer(link.queue, {"type": "welcome", "participant": session.participant, "consent": consent_text,
                       "view": session.study.config.live_view, "driving": session.study.config.live_driving,
                       "inputs": list(session.study.config.live_inputs)})
    previous, opening = (None, session.opening()) if link.closed else session.attach(link)
    if isinstance(previous, Link):
        previous.shut(REPLACED, "opened in another window",
                      {"type": "replaced", "detail": "This session was opened in another window or tab; "
                                                     "continue there."})
        offer(link.queue, {"type": "notice", "kind": "replaced",
                           "detail": "This session was open in another window or tab; that one is closed."})
    for message in opening:
        offer(link.queue, message)
    try:
        await receive_all(websocket, session, buckets, link, idle_seconds, sender)
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        session.detach(link)
        sender.cancel()


async def receive_all(websocket: WebSocket, session: Session, buckets: tuple[TokenBucket, ...],
                      link: Link, idle_seconds: float, sender: asyncio.Task) -> None:
    """Client messages until the socket closes; silence for idle_seconds closes it."""
    while not sender.done():
        receiving = asyncio.ensure_future(websocket.receive())
        done, _ = await asyncio.wait({receiving, sender}, timeout=idle_seconds,
                                     return_when=asyncio.FIRST_COMPLETED)
        if receiving not in done:
            receiving.cancel()
            if not done:   # silence: the socket is closed (a running episode pauses)
                link.shut(IDLE, "idle", {"type": "error", "code": "out_of_order",
                                         "detail": f"nothing received for {idle_seconds:g} s; closed"})
                with contextlib.suppress(asyncio.TimeoutError, asyncio.CancelledError):
                    await asyncio.wait_for(asyncio.shield(sender), 2.0)
            return
        raw = receiving.result()
        if raw["type"] == "websocket.disconnect":
            return
        if link.closed:   # revoked, replaced or idle: only its closing goes on
            continue
        data = raw["text"] if raw.get("text") is not None else (raw.get("bytes") or b"")
        for reply in respond(session, buckets[0], data, buckets[1], buckets[2]):
            offer(link.queue, reply)
        if session.phase == "declined":   # (their token is gone: LiveStudy.decline)
            revoke_stale(websocket, session.participant, "declined", "did not agree to take part")


def live_server(study: LiveStudy, sock):
    """The uvicorn server of `study` for the bound socket `sock` (its `run(sockets=[sock])` serves);
    the server's own origins are those of the socket's address; its connections capped
    (`ServerOptions.max_connections`, by default sized for the study: guard.connection_cap), and
    those of one address (`ServerOptions.connections_per_address`: guard.address_cap)."""
    import uvicorn

    host, port = sock.getsockname()[:2]
    app = live_app(study, own_origins(host, port))
    options = study.options
    cap = options.max_connections or connection_cap(study.config.participants)
    http = guarded_protocol(options.request_seconds, cap, options.connections_per_address)
    config = uvicorn.Config(app, log_level="warning", ws_max_size=4 * MAX_MESSAGE_BYTES, lifespan="off",
                            http=http, ws=GuardedWebSocketProtocol, timeout_keep_alive=5)
    return GuardedServer(config)


def serve(study: LiveStudy, sock, on_ready=None) -> None:
    """Run the application on the bound socket `sock` until interrupted (the study must be open)."""
    server = live_server(study, sock)
    if on_ready is not None:
        on_ready()
    server.run(sockets=[sock])
