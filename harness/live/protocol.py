"""The live study's messages: every websocket and HTTP message as a schema, the size cap, the flood
limit, and the error replies (docs/live_studies.md, "Protocol").

A participant's websocket carries JSON text messages of at most MAX_MESSAGE_BYTES (a binary frame
is refused). Each is validated against CLIENT_MESSAGE (a union on `type`; unknown keys, a key
given twice and wrong types are refused);
a message that is oversized, malformed, arrives faster than the connection's token bucket allows,
or does not fit the session's phase gets one `error` reply and changes nothing.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Annotated, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    StrictFloat,
    StrictInt,
    TypeAdapter,
    ValidationError,
    model_validator,
)

from trustroute.harness.live.auth import MAX_TOKEN_CHARS
from trustroute.harness.live.view import ROUTE_AHEAD, VIEW_RADIUS
from trustroute.harness.simulation.driving_style import AUTOPILOT, MANUAL
from trustroute.harness.study.config import LiveInput

MAX_MESSAGE_BYTES = 4096       # a websocket message larger than this is refused unread
MAX_BODY_BYTES = 16 * 1024     # an HTTP request body larger than this is refused (413)
BURST = 20                     # messages a connection may send at once ...
RATE = 10.0                    # ... and per second after that (token bucket)
CONTROL_RATE = 30.0            # `control` messages per second (their own bucket: a wheel streams)
SHOWN_RATE = 30.0              # `shown` messages per second (their own bucket: one per frame drawn)
TRUST_LOW, TRUST_HIGH = 1, 7   # the trust scale of reports (the authors' 1-7)


class Message(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ClientMessage(Message):
    """A message of the participant's websocket; `type` names it."""

    type: str


class Consent(ClientMessage):
    """The participant has read the consent text and agrees (`agree` true) or does not (false: the
    session ends, harness/live/server.py `LiveStudy.decline`); `client` says who drives (a person
    at the station, or the scripted participant): the episodes' parts record it. `lockstep`
    (scripted only): every episode waits for the participant's answer at each decision."""

    type: Literal["consent"]
    agree: StrictBool
    client: Literal["station", "scripted"] = "station"
    lockstep: StrictBool = False

    @model_validator(mode="after")
    def lockstep_is_scripted(self) -> Consent:
        if self.lockstep and self.client != "scripted":
            raise ValueError("lockstep is for the scripted participant only")
        return self


class Start(ClientMessage):
    """Start the next trial; `trust`: the participant's trust before it (1-7; default: the middle)."""

    type: Literal["start"]
    trust: Annotated[StrictInt, Field(ge=TRUST_LOW, le=TRUST_HIGH)] | None = None


class Takeover(ClientMessage):
    type: Literal["takeover"]


class HandBack(ClientMessage):
    type: Literal["hand_back"]


# The mode each asks the episode for (the ego's driving style, harness/simulation/driving_style.py).
REQUESTED_MODE = {"takeover": MANUAL.name, "hand_back": AUTOPILOT.name}


class Drive(ClientMessage):
    """Manual driving, in control only: `accelerate` or `brake` while the key or button is held,
    `release` when it is let go (the vehicle then holds the speed reached)."""

    type: Literal["drive"]
    pedal: Literal["accelerate", "brake", "release"]


class Steer(ClientMessage):
    """Manual driving, in control only: `oncoming` pulls out into the oncoming lane to pass an
    obstacle (as soon as the gap allows; back in the own lane once past it), `own` stays in (or
    returns to) the own lane."""

    type: Literal["steer"]
    lane: Literal["oncoming", "own"]


class Control(ClientMessage):
    """Continuous driving (`[live] driving = "continuous"`), in control only: the wheel and the
    pedals as they are now, steering -1 (full left) .. 1 (full right), pedals 0 .. 1. Sent at most
    CONTROL_RATE times a second, counted by a token bucket of its own. `source`: the input read
    (one of the study's `[live] inputs`: a control from another is refused)."""

    type: Literal["control"]
    source: LiveInput
    steer: Annotated[float, Field(ge=-1.0, le=1.0, allow_inf_nan=False)]
    throttle: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
    brake: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]


class Pass(ClientMessage):
    """Lockstep: the answer "no takeover" to an `incident` event."""

    type: Literal["pass"]


class PromptId(Message):
    """A prompt for a report: the episode and the road (its index in the roads table) it asks about."""

    episode_id: Annotated[str, Field(min_length=1, max_length=64)]
    road: Annotated[StrictInt, Field(ge=1, le=1_000_000)]


class TrustReport(ClientMessage):
    """A trust report; `prompt`: the prompt it answers (the road event's), none for a report given
    outside a prompt."""

    type: Literal["trust"]
    value: Annotated[StrictInt, Field(ge=TRUST_LOW, le=TRUST_HIGH)]
    prompt: PromptId | None = None


class Answers(ClientMessage):
    """The answers to the questionnaire shown: {item id: scale point} for every item."""

    type: Literal["answers"]
    questionnaire: Annotated[str, Field(pattern=r"^[a-z0-9_-]{1,40}$")]
    answers: Annotated[dict[Annotated[str, Field(max_length=40)], StrictInt | StrictFloat],
                       Field(max_length=100)]


class Resume(ClientMessage):
    """Resume an episode paused by this participant's disconnect."""

    type: Literal["resume"]


class Ping(ClientMessage):
    type: Literal["ping"]


class Shown(ClientMessage):
    """The station has drawn the frame of simulated time `t` (sent for each frame it draws): the
    episode runs at most STATION_LEAD simulated seconds ahead of what the person has seen
    (harness/live/worker.py). Counted by a token bucket of its own (SHOWN_RATE); ignored outside
    an episode."""

    type: Literal["shown"]
    t: Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


CLIENT_MESSAGE = TypeAdapter(Annotated[Consent | Start | Takeover | HandBack | Drive | Steer | Control
                                       | Pass | TrustReport | Answers | Resume | Ping | Shown,
                                       Field(discriminator="type")])


# -- server messages ------------------------------------------------------------------------------
class Reported(Message):
    """Server -> client: a trust report accepted and passed to the running episode (the station
    says "You reported N." on this, not on sending: a refused report is not one); `prompt`: the
    prompt it answers, as the report named it."""

    type: Literal["reported"] = "reported"
    value: Annotated[StrictInt, Field(ge=TRUST_LOW, le=TRUST_HIGH)]
    prompt: PromptId | None = None


Finite = Annotated[float, Field(allow_inf_nan=False)]
# What the ego sees (harness/live/view.py `surroundings`): the items of a vehicle and of a person,
# in their order; the types below hold the same items in the same order.
SEEN_VEHICLE = ("x", "y", "angle", "kind", "speed", "handle", "length", "width", "height", "shape", "signals")
SEEN_PERSON = ("x", "y", "kind", "handle", "angle")
SeenVehicle = tuple[Finite, Finite, Finite, str, Finite, StrictInt, Finite, Finite, Finite, str, StrictInt]
SeenPerson = tuple[Finite, Finite, str, StrictInt, Finite]


def driving_mode(name: str) -> str:
    """`name` when it is a driving style's (harness/simulation/driving_style.py), else ValueError."""
    if name not in (AUTOPILOT.name, MANUAL.name):
        raise ValueError(f"a mode is {AUTOPILOT.name!r} or {MANUAL.name!r}, not {name!r}")
    return name


class Frame(Message):
    """Server -> client: one moment of the episode as the station shows it (docs/live_studies.md,
    "Protocol"; built by harness/live/worker.py, which validates every stepped frame against this).
    Each field's description is the one text of what it holds, which the docs' table of the frame
    shows (tests/test_docs_frame.py keeps the two equal)."""

    type: Literal["frame"] = Field("frame", description="`frame`")
    t: Annotated[float, Field(ge=0.0, allow_inf_nan=False)] = Field(
        description="the simulated time of the frame, seconds")
    x: Finite = Field(description="the ego's front centre, metres east in the net's (SUMO's) coordinates")
    y: Finite = Field(description="the ego's front centre, metres north in the net's (SUMO's) coordinates")
    angle: Finite = Field(description="the ego's heading, SUMO's: degrees clockwise from north")
    speed: Finite = Field(description="the ego's speed, m/s")
    road: str = Field(description="the road under observation, a town road `A-B`: the one a takeover "
                                  "counts for, from the commit point 30 m before the end of the road before "
                                  "it (the ego may still be on that road, or in the junction: `lane` says "
                                  "where it is)")
    lane: str = Field(description="the ego's lane (SUMO's id)")
    mode: Annotated[str, AfterValidator(driving_mode)] = Field(
        description=f"who drives: `{AUTOPILOT.name}` (the autopilot) or `{MANUAL.name}` (the person)")
    junction: str | None = Field(
        description="the junction at the end of `road`: where the next routing decision is made")
    length: Finite = Field(description="the ego's length, metres")
    width: Finite = Field(description="the ego's width, metres")
    signals: StrictInt = Field(description="the ego's signals, SUMO's bits as in `vehicles`")
    route: list[str] = Field(
        description=f"the roads of the ego's route from the one it is on, at most {ROUTE_AHEAD} "
                    "(harness/live/view.py `ROUTE_AHEAD`)")
    vehicles: list[SeenVehicle] = Field(
        description=f"every other vehicle within {VIEW_RADIUS:g} m (harness/live/view.py `VIEW_RADIUS`), "
                    f"each `[{', '.join(SEEN_VEHICLE)}]`: (x, y) its front centre and `angle` as the "
                    "ego's; `kind` `traffic` or an incident object's role: `obstacle`, `oncoming` (the "
                    "obstacle scene's truck), `truck` (the truck scene's), `parked`, `pedestrian`; `handle` "
                    "a number stable within the episode (no SUMO id reaches the page); `shape` SUMO's shape "
                    "class; `signals` SUMO's bits 1 (right indicator), 2 (left), 4 (hazard lights), 8 "
                    "(brake light)")
    persons: list[SeenPerson] = Field(
        description=f"every person within {VIEW_RADIUS:g} m, each `[{', '.join(SEEN_PERSON)}]`, as in "
                    "`vehicles`")
    held: StrictBool = Field(
        description="by wheel: the car is brought to a stand for the hand-back whatever the pedals say, by "
                    "the episode's one rule (harness/simulation/wheel_driving.py `Wheel.held`); the station "
                    "then sends the pedals let go, and no steering once the car stands. Always false in "
                    "assisted driving, where the `hand_back` warning says the vehicle stops")
    predicted: StrictBool = Field(
        False, description="true on a frame between two SUMO steps: the last stepped frame moved on "
                           "(harness/live/view.py `dead_reckoned`), never the simulation's state")


# -- HTTP bodies ---------------------------------------------------------------------------------
class NewParticipant(Message):
    label: Annotated[str, Field(max_length=100, pattern=r"^[\w .,:()-]*$")] = ""


class LinkClaim(Message):
    """The token of a participant's link, claimed by the link's page."""

    token: Annotated[str, Field(min_length=1, max_length=MAX_TOKEN_CHARS)]


def confirmed(value: bool) -> bool:
    if not value:
        raise ValueError("a withdrawal needs confirm: true")
    return value


class Withdrawal(Message):
    """The experimenter withdraws a participant: `confirm` must be the JSON `true` (the console
    asks first); a StrictBool, since a Literal[True] takes 1 and 1.0 as equal to it."""

    confirm: Annotated[StrictBool, AfterValidator(confirmed)]
    reason: Annotated[str, Field(max_length=300, pattern=r"^[\w .,:;()'/-]*$")] = ""


class EpisodeControl(Message):
    """The experimenter's control of a participant's running episode."""

    action: Literal["pause", "resume", "abort"]


# -- errors and limits ---------------------------------------------------------------------------
ERROR_CODES: tuple[str, ...] = ("oversized", "malformed", "rate_limited", "out_of_order", "forbidden",
                                "not_found")


def error_reply(code: str, detail: str) -> dict:
    if code not in ERROR_CODES:
        raise ValueError(f"unknown error code {code!r}")
    return {"type": "error", "code": code, "detail": detail[:300]}


class MessageError(Exception):
    """A client message refused before it reached the session (its reply in `reply`)."""

    def __init__(self, code: str, detail: str) -> None:
        super().__init__(detail)
        self.reply = error_reply(code, detail)


def unique_keys(pairs: list[tuple[str, object]]) -> dict:
    """`json.loads`' object_pairs_hook: an object naming a key twice is refused (MessageError
    `malformed`), where a JSON parser would silently keep one of the two values."""
    seen: set[str] = set()
    for key, _ in pairs:
        if key in seen:
            raise MessageError("malformed", f"the key {key[:40]!r} is given twice")
        seen.add(key)
    return dict(pairs)


def json_value(text: str | bytes, what: str) -> object:
    """`text` (a websocket message or an HTTP body: `what`) read as JSON, once: MessageError
    `malformed` for an object naming a key twice or nesting deeper than the parser goes,
    json.JSONDecodeError for text that is no JSON (bytes are read as UTF-8, JSON's one encoding:
    no other, no byte-order mark; an integer longer than Python converts is no JSON either). NaN,
    Infinity and numbers beyond a float's range (1e400) read as the floats pydantic's JSON mode
    reads, so each schema refuses them where it would refuse them in JSON (a finite number field)
    and takes them where it would take them."""
    try:
        return json.loads(text.decode() if isinstance(text, bytes) else text, object_pairs_hook=unique_keys)
    except RecursionError:
        raise MessageError("malformed", f"the {what} is nested too deeply") from None
    except json.JSONDecodeError:
        raise
    except ValueError as exc:   # bytes that are no UTF-8, an integer longer than Python converts
        raise json.JSONDecodeError(str(exc), "", 0) from None


def parse_client_message(raw: str | bytes) -> ClientMessage:
    """The validated message, or MessageError (binary, oversized or malformed). The text is parsed
    once (`json_value`) and the value validated against CLIENT_MESSAGE."""
    if not isinstance(raw, str):
        raise MessageError("malformed", "a message is JSON text, not a binary frame")
    size = len(raw.encode())
    if size > MAX_MESSAGE_BYTES:
        raise MessageError("oversized", f"{size} bytes; a message holds at most {MAX_MESSAGE_BYTES}")
    try:
        return CLIENT_MESSAGE.validate_python(json_value(raw, "message"))
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first.get("loc", ())) or "message"
        raise MessageError("malformed", f"{where}: {first.get('msg', 'invalid')}") from None
    except ValueError as exc:
        raise MessageError("malformed", f"not a JSON message ({exc})") from None


@dataclass
class TokenBucket:
    """A flood limit per connection: `burst` messages at once, `rate` per second after that."""

    burst: float = BURST
    rate: float = RATE
    clock: Callable[[], float] = time.monotonic
    tokens: float = field(default=-1.0)
    last: float = field(default=0.0)

    def __post_init__(self) -> None:
        self.tokens = float(self.burst)
        self.last = self.clock()

    def take(self) -> bool:
        """Whether one more message is allowed now (it uses up one token if so)."""
        self.refill()
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False

    def seconds_to_next(self) -> float:
        """How long until `take` would allow one more message (0.0: now)."""
        self.refill()
        return max(0.0, (1.0 - self.tokens) / self.rate)

    def refill(self) -> None:
        now = self.clock()
        self.tokens = min(float(self.burst), self.tokens + (now - self.last) * self.rate)
        self.last = now
