"""Who a live-study request is: the experimenter, one participant, or no one.

Tokens come from `secrets.token_urlsafe` (32 bytes). The server keeps only their SHA-256 (the
experimenter's in memory for the server's life; the participants' in the study directory, so a
participant's link survives a restart) and compares digests with `secrets.compare_digest`. A token
arrives in an HttpOnly, SameSite=Strict cookie set by the link a person opens, or (scripts, the
scripted participant) in an `Authorization: Bearer` header. A participant token names exactly one
participant: the session it acts on is the one it names, never one chosen by the request.

The experimenter has three kinds: the experimenter token (printed at start, for scripts: Bearer
only, never in an address), one-time login tokens (the console link's: the first use spends it,
`spend_login`) and the session tokens a login puts in the browser's cookie. A console session
unused for CONSOLE_IDLE_SECONDS is refused from then on (`console_expired` tells it from a token
never known): a cookie left in a browser the experimenter walked away from does not open the
console for good. An open console asks the server every second, so it stays logged in.
"""

from __future__ import annotations

import hashlib
import secrets
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

EXPERIMENTER_COOKIE = "trustroute_experimenter"
PARTICIPANT_COOKIE = "trustroute_participant"
TOKEN_BYTES = 32
MAX_TOKEN_CHARS = 128   # longer is no token of ours: refused before hashing
# A console session unused this long is refused: long enough for a day of sessions with breaks
# (the console, open, keeps it in use), short enough that a browser left logged in overnight is not.
CONSOLE_IDLE_SECONDS = 12 * 3600


def new_token() -> str:
    return secrets.token_urlsafe(TOKEN_BYTES)


def token_digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def well_formed(token: str | None) -> str | None:
    """`token`, or None when it cannot be one of ours (empty, longer than MAX_TOKEN_CHARS, not
    ASCII): such a token is refused before it is hashed."""
    if not token or len(token) > MAX_TOKEN_CHARS or not token.isascii():
        return None
    return token


def presented_token(headers: Mapping[str, str], cookies: Mapping[str, str], cookie: str) -> str | None:
    """The token a request carries: the Bearer header first, else the named cookie; None when
    there is none or it cannot be one of ours (`well_formed`)."""
    authorization = headers.get("authorization", "")
    return well_formed(authorization[7:].strip() if authorization.lower().startswith("bearer ")
                       else cookies.get(cookie))


@dataclass
class Credentials:
    """The experimenter's token digest, their console sessions' (digest -> the `clock`'s time of
    its last use; those gone unused for CONSOLE_IDLE_SECONDS in `expired`) and their unspent login
    link's; each participant's (participant index -> digest)."""

    experimenter_digest: str
    participants: dict[int, str] = field(default_factory=dict)
    consoles: dict[str, float] = field(default_factory=dict)
    expired: set[str] = field(default_factory=set)
    login_digest: str | None = None
    clock: Callable[[], float] = time.monotonic
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def is_experimenter(self, token: str | None) -> bool:
        """The experimenter token or a console session's still in use, whose use it counts as
        (every digest compared: no early exit)."""
        if token is None:
            return False
        digest = token_digest(token)
        with self.lock:
            self.expire_idle()
            matched = [each for each in self.consoles if secrets.compare_digest(digest, each)]
            for each in matched:
                self.consoles[each] = self.clock()
        scripts = secrets.compare_digest(digest, self.experimenter_digest)
        return scripts or bool(matched)

    def console_expired(self, token: str | None) -> bool:
        """Whether `token` is a console session's refused for going unused (is_experimenter)."""
        if token is None:
            return False
        digest = token_digest(token)
        with self.lock:
            self.expire_idle()
            return any([secrets.compare_digest(digest, each) for each in self.expired])

    def expire_idle(self) -> None:
        """Move the console sessions unused for CONSOLE_IDLE_SECONDS to `expired` (lock held)."""
        now = self.clock()
        for digest, used in list(self.consoles.items()):
            if now - used >= CONSOLE_IDLE_SECONDS:
                del self.consoles[digest]
                self.expired.add(digest)

    def new_login(self) -> str:
        """A one-time login token (returned once); it replaces an unspent one."""
        token = new_token()
        self.login_digest = token_digest(token)
        return token

    def spend_login(self, token: str | None) -> str | None:
        """A fresh console session token for the unspent login token `token` (which is spent), or
        None for any other token. (The caller serializes calls: a link is spent once.)"""
        if token is None or self.login_digest is None:
            return None
        if not secrets.compare_digest(token_digest(token), self.login_digest):
            return None
        self.login_digest = None
        session = new_token()
        with self.lock:
            self.consoles[token_digest(session)] = self.clock()
        return session

    def participant_of(self, token: str | None) -> int | None:
        """The participant the token names, or None. Every digest is compared (no early exit)."""
        if token is None:
            return None
        digest, found = token_digest(token), None
        for participant, known in self.participants.items():
            if secrets.compare_digest(digest, known):
                found = participant
        return found

    def add_participant(self, participant: int) -> str:
        """A fresh token for `participant` (returned once: only its digest is kept)."""
        token = new_token()
        self.participants[participant] = token_digest(token)
        return token


def experimenter_credentials() -> tuple[Credentials, str]:
    """(credentials with a fresh experimenter token, that token)."""
    token = new_token()
    return Credentials(experimenter_digest=token_digest(token)), token
