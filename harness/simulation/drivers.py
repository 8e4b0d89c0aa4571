"""Who sits in the ego: the typed drivers an episode is driven with.

- `Driver`: what every episode asks of its driver (participants/synthetic_driver.py
  SyntheticDriver; a live study's remote person, harness/live/worker.py, answers the same calls):
  the true trust, the takeover decision when an incident comes into view, the trust move when a
  road's observation closes, and a trust report when one is due.
- `PersonControls`: a person at the wheel (a live study's station). The episode asks them every
  step for a takeover or hand-back, and, when they drive by hand, for the pedal and the pull-out
  they set (manual_driving.py applies them and the hold before the hand-back). A person is given
  to the episode as its `PersonControls` beside the `Driver`, never found by probing the driver.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

Pedal = Literal["accelerate", "brake", "release"]
Steer = Literal["oncoming", "own"]


class Driver(Protocol):
    """The driver of an episode (takeover_decision.py and the episode's road ends call these)."""

    @property
    def trust(self) -> int: ...

    def decides_takeover(self, incident: str) -> bool: ...

    def move_trust(self, incident: str, took_over: bool, performance: str = "succ") -> int: ...

    def report_trust(self) -> int | None: ...


@dataclass(frozen=True)
class ManualInputs:
    """What a person driving by hand set since the episode last asked: the pedal now held (None:
    unchanged) and a pull-out into the oncoming lane or back into their own (None: none)."""

    pedal: Pedal | None = None
    steer: Steer | None = None


NO_INPUTS = ManualInputs()


class PersonControls(Protocol):
    """A person at the wheel, read by the episode every step.

    drives_by_hand: in control, the person's pedals and pull-out drive the ego and the ego waits
    short of the road's end for their hand-back (manual_driving.py); False: a takeover drives on
    SUMO's manual style and ends at the commit point, as in simulated studies (the scripted
    participant's lockstep)."""

    @property
    def drives_by_hand(self) -> bool: ...

    def takeover_request(self, now: float) -> bool | None:
        """True: take over, False: hand back, None: neither (asked every step)."""
        ...

    def manual_inputs(self) -> ManualInputs:
        """The pedal and pull-out set since the last call."""
        ...

    def hand_back_warning(self, distance: float, now: float) -> None:
        """The person is still in control `distance` metres before the road's end: tell them to
        hand back."""
        ...

    def drive_on(self, chain: Callable[[str], tuple[str, ...]]) -> None:
        """The SUMO edges each road of the episode runs along, in driving order (episode_roads.py
        `EpisodeRoads.chain`), given before the episode's first step."""
        ...
