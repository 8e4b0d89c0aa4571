"""Who a live-study request is: the experimenter, one participant, or no one.

Tokens come from `secrets.token_urlsafe` (32 bytes). The server keeps only their SHA-256 (the
experimenter's in memory for the server's life; the participants' in the study directory, so a
participant's link survives a restart) and compares digests with `secrets.compare_digest`. A token
arrives in an HttpOnly, SameSite=Strict cookie set by the link a person opens, or (scripts, the
scripted participant) in an `Authorization: Bearer` header. A participant token names exactly one
participant: the session it acts on is the one it names, never one chosen by the request.

The experimenter has three kinds: the experimenter token (printed at start, for scripts: Bearer
only, never in an address), one-time login tokens (the console link's: the first use spends it,
`spend_login`) and the session tokens a login puts in the browser's cookie.
"""

from __future__ import annotations

import hashlib
import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field

EXPERIMENTER_COOKIE = "trustroute_experimenter"
PARTICIPANT_COOKIE = "trustroute_participant"
TOKEN_BYTES = 32
MAX_TOKEN_CHARS = 128   # longer is no token of ours: refused before hashing


def new_token() -> str:
    return secrets.token_urlsafe(TOKEN_BYTES)


def token_digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def presented_token(headers: Mapping[str, str], cookies: Mapping[str, str], cookie: str) -> str | None:
    """The token a request carries: the Bearer header first, else the named cookie; None when
    there is none or it cannot be one of ours (too long, not ASCII)."""
    authorization = headers.get("authorization", "")
    token = authorization[7:].strip() if authorization.lower().startswith("bearer ") else cookies.get(cookie)
    if not token or len(token) > MAX_TOKEN_CHARS or not token.isascii():
        return None
    return token


@dataclass
class Credentials:
    """The experimenter's token digest, their open console sessions' and their unspent login
    link's; each participant's (participant index -> digest)."""

    experimenter_digest: str
    participants: dict[int, str] = field(default_factory=dict)
    consoles: list[str] = field(default_factory=list)
    login_digest: str | None = None

    def is_experimenter(self, token: str | None) -> bool:
        """The experimenter token or a console session's (every digest compared: no early exit)."""
        if token is None:
            return False
        digest = token_digest(token)
        known = (self.experimenter_digest, *self.consoles)
        return any([secrets.compare_digest(digest, each) for each in known])

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
        self.consoles.append(token_digest(session))
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
