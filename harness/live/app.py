"""The live study's web application (FastAPI): HTTP API, participant websocket, links.

Every route checks who is asking (harness/live/auth.py) before it reads anything:

    GET  /login?token=T                experimenter: sets the HttpOnly cookie, then to /console
    GET  /p/{token}                    a participant's link: sets their cookie, then to /station
    GET  /console, /station            the pages (experimenter; participant), plain HTML and JS
    GET  /static/{name}                their script and style sheet
    GET  /api/me                       participant: their own progress and the consent text
    GET  /api/net                      participant or experimenter: the net's lanes (the view)
    POST /api/participants             experimenter: create the next participant -> link
    GET  /api/participants             experimenter: every participant's progress
    GET  /api/participants/{p}         experimenter, or participant p themself
    POST /api/participants/{p}/control experimenter: pause, resume or abort p's episode
    GET  /api/files                    experimenter: the study directory's files
    GET  /api/download/{path}          experimenter: one file, inside the study directory only
    WS   /ws                           participant: the protocol of harness/live/protocol.py

Request bodies are capped (MAX_BODY_BYTES) and validated (protocol.py models); every refusal is
a JSON error of the protocol's form with an HTTP status, and changes nothing. `serve` runs the application
on uvicorn (websocket frames capped at the transport too).
"""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path

from fastapi import APIRouter, Depends, FastAPI, HTTPException, Request, WebSocket, WebSocketDisconnect
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, RedirectResponse
from starlette.requests import HTTPConnection

from trustroute.harness.live.auth import EXPERIMENTER_COOKIE, PARTICIPANT_COOKIE, presented_token
from trustroute.harness.live.protocol import (
    CONTROL_RATE,
    MAX_BODY_BYTES,
    MAX_MESSAGE_BYTES,
    EpisodeControl,
    MessageError,
    NewParticipant,
    TokenBucket,
    error_reply,
    parse_client_message,
)
from trustroute.harness.live.server import LiveStudy
from trustroute.harness.live.session import Session

PAGES = Path(__file__).with_name("pages")
# The driver's view renders with three.js, shipped in pages/vendor/ with its licence (pinned:
# docs/live_studies.md), so no page loads a script from elsewhere.
STATIC = {"live.css": "text/css", "console.js": "text/javascript", "station.js": "text/javascript",
          "driver_view.js": "text/javascript", "map_view.js": "text/javascript",
          "inputs.js": "text/javascript",
          "vendor/three.module.js": "text/javascript", "vendor/three.core.js": "text/javascript"}
# Every response: no framing, no sniffing, no referrer (a participant link carries a token), and
# scripts, styles and sockets from this server only.
SECURITY_HEADERS = {"X-Content-Type-Options": "nosniff", "X-Frame-Options": "DENY",
                    "Referrer-Policy": "no-referrer", "Cache-Control": "no-store",
                    "Content-Security-Policy": "default-src 'self'; connect-src 'self'; "
                                               "img-src 'self' data:; frame-ancestors 'none'"}
OUTBOX = 1024          # messages queued for one websocket; frames are dropped first
FRAMES_UP_TO = OUTBOX // 2
POLICY_VIOLATION = 1008  # websocket close code: no valid participant token


def offer(queue: asyncio.Queue, message: dict) -> None:
    """Queue a message for the socket; a frame is dropped when the socket is behind."""
    if message.get("type") == "frame" and queue.qsize() >= FRAMES_UP_TO:
        return
    with contextlib.suppress(asyncio.QueueFull):
        queue.put_nowait(message)


def respond(session: Session, bucket: TokenBucket, data: str | bytes,
            controls: TokenBucket | None = None) -> list[dict]:
    """The replies to one raw client message (an error reply for a refused one). A wheel's
    `control` messages count against `controls`, every other message against `bucket`."""
    try:
        message = parse_client_message(data)
    except MessageError as exc:
        return [exc.reply] if bucket.take() else [error_reply("rate_limited", "too many messages; slow down")]
    if not (controls if controls is not None and message.type == "control" else bucket).take():
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


router = APIRouter()


def study_of(connection: HTTPConnection) -> LiveStudy:
    return connection.app.state.study


def experimenter(request: Request) -> None:
    """Dependency: the request carries the experimenter's token (401 without a token, 403 with another)."""
    token = presented_token(request.headers, request.cookies, EXPERIMENTER_COOKIE)
    if not study_of(request).credentials.is_experimenter(token):
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


async def limit_body(request: Request, call_next):
    """Bodies need a length within MAX_BODY_BYTES; every response gets the security headers."""
    response = None
    if request.method in ("POST", "PUT", "PATCH"):
        length = request.headers.get("content-length", "")
        if not length.isdigit():
            response = JSONResponse({"type": "error", "detail": "a body needs a Content-Length"}, 411)
        elif int(length) > MAX_BODY_BYTES:
            limit = f"bodies hold at most {MAX_BODY_BYTES} bytes"
            response = JSONResponse(error_reply("oversized", limit), 413)
    if response is None:
        response = await call_next(request)
    response.headers.update(SECURITY_HEADERS)
    return response


async def malformed(request: Request, exc: Exception) -> JSONResponse:
    errors = exc.errors() if isinstance(exc, RequestValidationError) else []
    first = errors[0] if errors else {}
    where = ".".join(str(part) for part in first.get("loc", ()))
    return JSONResponse(error_reply("malformed", f"{where}: {first.get('msg', 'invalid')}"), 422)


@router.get("/login")
def login(request: Request, token: str = "") -> RedirectResponse:
    if not study_of(request).credentials.is_experimenter(token[:200] or None):
        raise refused(403, "forbidden", "the experimenter's token is needed")
    return cookie_redirect(request, "/console", EXPERIMENTER_COOKIE, token)


@router.get("/p/{token}")
def participant_link(request: Request, token: str) -> RedirectResponse:
    if study_of(request).credentials.participant_of(token[:200]) is None:
        raise refused(403, "forbidden", "not a participant link of this study")
    return cookie_redirect(request, "/station", PARTICIPANT_COOKIE, token)


@router.get("/console", dependencies=[Depends(experimenter)])
def console() -> FileResponse:
    return FileResponse(PAGES / "console.html", media_type="text/html")


@router.get("/station", dependencies=[Depends(participant_token)])
def station() -> FileResponse:
    return FileResponse(PAGES / "station.html", media_type="text/html")


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
    study = study_of(websocket)
    participant = study.credentials.participant_of(
        presented_token(websocket.headers, websocket.cookies, PARTICIPANT_COOKIE))
    if participant is None:
        await websocket.close(code=POLICY_VIOLATION)
        return
    await websocket.accept()
    await converse(websocket, study.sessions[participant], study.consent_text)


def live_app(study: LiveStudy) -> FastAPI:
    """The application serving `study` (opened: credentials and directory lock held)."""
    app = FastAPI(title="trustroute live", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.study = study
    app.middleware("http")(limit_body)
    app.add_exception_handler(RequestValidationError, malformed)
    app.include_router(router)
    return app


async def converse(websocket: WebSocket, session: Session, consent_text: str) -> None:
    """One participant connection: replies and the episode's messages out, client messages in."""
    queue: asyncio.Queue = asyncio.Queue(maxsize=OUTBOX)
    loop = asyncio.get_running_loop()

    def push(message: dict) -> None:   # called from the episode's reader thread
        loop.call_soon_threadsafe(offer, queue, message)

    async def send_all() -> None:
        while True:
            await websocket.send_json(await queue.get())

    sender = asyncio.create_task(send_all())
    bucket, controls = TokenBucket(), TokenBucket(burst=CONTROL_RATE, rate=CONTROL_RATE)
    offer(queue, {"type": "welcome", "participant": session.participant, "consent": consent_text,
                  "view": session.study.config.live_view,
                  "driving": session.study.config.live_driving})
    offer(queue, session.progress())
    session.attach(push)
    try:
        while True:
            raw = await websocket.receive()
            if raw["type"] == "websocket.disconnect":
                break
            data = raw["text"] if raw.get("text") is not None else (raw.get("bytes") or b"")
            for reply in respond(session, bucket, data, controls):
                offer(queue, reply)
    except WebSocketDisconnect:
        pass
    finally:
        session.detach(push)
        sender.cancel()


def serve(study: LiveStudy, host: str, port: int, on_ready=None) -> None:
    """Run the application on uvicorn until interrupted (the study must be open)."""
    import uvicorn

    config = uvicorn.Config(live_app(study), host=host, port=port, log_level="warning",
                            ws_max_size=4 * MAX_MESSAGE_BYTES, lifespan="off")
    server = uvicorn.Server(config)
    if on_ready is not None:
        on_ready()
    server.run()
