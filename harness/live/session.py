"""One participant's session: the phase it is in, its trials, its running episode.

Phases: "consent" (the consent text is shown) -> "ready" (a trial can start) -> "driving" <->
"paused" -> "ready" ... -> "done" (every trial of the participant has a part), or "consent" ->
"declined" (they did not agree: nothing of theirs is kept, every message refused); with the study's
questionnaires, "questionnaire" (one is shown) comes after the consent, after a trial and at the
end, until each is answered. A client message
that does not fit the phase (a takeover before consent, a hand-back on autopilot, a resume of the
experimenter's pause) is refused with an `out_of_order` error and changes nothing; a hand-back that
crosses the episode's own at the junction, or the drive's end, is not one (`Session.switch`).

The trials are the participant's planned episodes in the study's order (harness/study/plan.py);
a trial is done when its part exists, so an aborted, failed or interrupted episode is run again
at the participant's next start, and a restarted server continues at the first trial without a
part. State changes happen under one lock: client messages arrive on the server's event loop, the
episode's messages on the session's reader thread.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any

from trustroute.harness.live.answers import answered, save_answers
from trustroute.harness.live.attempts import outcome_of
from trustroute.harness.live.protocol import (
    REQUESTED_MODE,
    Answers,
    ClientMessage,
    Consent,
    Control,
    Drive,
    HandBack,
    MessageError,
    Pass,
    Ping,
    Reported,
    Resume,
    Shown,
    Start,
    Steer,
    Takeover,
    TrustReport,
)
from trustroute.harness.live.withdraw import declined
from trustroute.harness.live.worker import start_episode_process
from trustroute.harness.simulation.driving_style import AUTOPILOT
from trustroute.harness.study.plan import EpisodeTask
from trustroute.participants.questionnaires import Questionnaire

STOP_SECONDS = 5.0


def withdrawn_refusal(participant: int) -> str:
    """Why nothing more is done for a withdrawn participant (no episode control, no new link): the
    withdrawal is final while the server runs (a readmission needs it stopped)."""
    return (f"participant {participant} has withdrawn from the study: their session is over and "
            "their data deleted")


# The experimenter console's actions on a participant (harness/live/app.py) that each phase of
# their session accepts: the episode controls need a running episode; a new link is refused only
# once they have withdrawn (for one who declined it asks for their consent again), a withdrawal
# once they have withdrawn or declined (nothing of theirs is kept). Two pauses are not the
# experimenter's to resume (`Session.console_phase`): one the participant's disconnect made
# ("disconnected"), whether or not they are back yet, is theirs (their station says "Press Resume"),
# and one the experimenter made while the participant has left their station ("away") waits for
# them to come back: the car would drive with no one at the station, or before the person pressed
# Resume, and the deadline of a disconnect's pause (`expire`) would be lifted. The server refuses
# any other action (`console_refusal`), and the state carries the list (`actions`), so the console
# shows a button for exactly these.
CONSOLE_ACTIONS: dict[str, tuple[str, ...]] = {
    "consent": ("link", "withdraw"),
    "declined": ("link",),
    "questionnaire": ("link", "withdraw"),
    "ready": ("link", "withdraw"),
    "driving": ("pause", "abort", "link", "withdraw"),
    "paused": ("resume", "abort", "link", "withdraw"),
    "disconnected": ("abort", "link", "withdraw"),
    "away": ("abort", "link", "withdraw"),
    "done": ("link", "withdraw"),
    "withdrawn": (),
}


def console_refusal(participant: int, phase: str, action: str) -> str | None:
    """Why the console's `action` on `participant`, in `phase` (`Session.console_phase`), is
    refused; None when it is accepted (CONSOLE_ACTIONS)."""
    if action in CONSOLE_ACTIONS[phase]:
        return None
    accepted = ", ".join(CONSOLE_ACTIONS[phase])
    if phase == "withdrawn":
        why = withdrawn_refusal(participant)
    elif phase == "declined":
        why = "{} ({})".format(*declined(participant))
    elif phase == "disconnected":
        why = (f"participant {participant}'s episode is paused by their disconnect: they resume it at "
               f"their station, and it accepts {accepted}")
    elif phase == "away":
        why = (f"participant {participant} is not at their station: their paused episode waits for them "
               f"to come back, and accepts {accepted}")
    else:
        why = f"participant {participant} is in phase {phase!r}, which accepts {accepted}"
    return f"no {action}: {why}"


def drive_named(trial: int, trials: int, warm_up: bool) -> str:
    """The drive in the participant's words, as a sentence begins: "The warm-up drive" or "Trial 2
    of 3" (`trial` as `station_texts` has it)."""
    return "The warm-up drive" if warm_up else f"Trial {trial} of {trials}"


# What the station says once a drive ends, by the attempt's outcome (harness/live/attempts.py
# `outcome_of`, the journal's rule): every end but "done" leaves the drive to be run again.
DRIVE_ENDS = {"done": "{drive} is complete.",
              "aborted": "{drive} was stopped by the experimenter; it will be run again.",
              "incomplete": "{drive} was stopped: the connection was lost for too long. "
                            "It will be run again.",
              "failed": "{drive} failed for a technical reason; it will be run again."}


def station_texts(phase: str, trial: int, trials: int, warm_up: bool) -> dict[str, str | None]:
    """Where the participant is among their `trials`, in the participant's words, which the station
    shows as they are (the console's words: `Session.trial_status`): `status`, its status line
    ("Warm-up drive", "Trial 2 of 3" while driven, "Trial 2 of 3 is next" before it); `next`, the
    start step's sentence (null outside phase "ready"). `trial` is the state's (the trials done,
    plus the one driven); `warm_up`: the drive under way, or the next, is the warm-up. What is said
    once the drive ends comes with its end (`station_end`)."""
    if phase in ("driving", "paused"):
        return {"status": "Warm-up drive" if warm_up else drive_named(trial, trials, False), "next": None}
    if phase != "ready":
        return {"status": "", "next": None}
    if warm_up:
        return {"status": "Warm-up drive", "next": "Next: a warm-up drive, to get to know the vehicle."}
    return {"status": f"Trial {trial + 1} of {trials} is next",
            "next": f"Next: trial {trial + 1} of {trials}."}


def station_end(message: dict, trial: int, trials: int, warm_up: bool) -> str:
    """What the station says of the drive that the episode's last `message` ended (its `station`
    field), in the words of `station_texts`: "Trial 2 of 3 is complete.", "The warm-up drive was
    stopped by the experimenter; it will be run again." (`DRIVE_ENDS`)."""
    return DRIVE_ENDS[outcome_of(message)[0]].format(drive=drive_named(trial, trials, warm_up))


class Session:
    """A participant's session (one per participant, whether or not a browser is connected)."""

    def __init__(self, study, participant: int, tasks: list[EpisodeTask], label: str = "",
                 consented: bool = False, client: str = "station", warm_up: EpisodeTask | None = None,
                 warmed_up: bool = False) -> None:
        self.study = study                  # harness/live/server.py LiveStudy
        self.participant = participant
        self.tasks = tasks
        self.warm_up = warm_up            # the warm-up drive before the trials (None: none)
        self.warmed_up = warmed_up
        self.label = label
        self.client = client
        self.lockstep = False
        # Taken before the study's lock whenever both are held (harness/live/server.py, LiveStudy.lock).
        self.lock = threading.RLock()
        self.phase = "ready" if consented else "consent"
        self.pause_reason: str | None = None
        self.task: EpisodeTask | None = None
        self.mode = "auto"
        self.asked = "auto"              # the mode the participant's last takeover or hand-back asked for
        self.switched_unasked = False    # the episode switched to `mode` on its own since then
        self.frame: dict | None = None   # the running drive's newest frame (`road`, `opening`)
        self.reports = self.takeovers = 0
        self.prompted: set[int] = set()   # the roads the running episode has asked a report about
        self.last_error: str | None = None
        self.process: Any = None
        self.connection: Any = None      # the episode process and our end of its pipe
        self.push: Callable[[dict], None] | None = None
        self.expiry: threading.Timer | None = None   # the deadline of a disconnect's pause
        if consented:
            self.phase = self.next_phase()

    # -- what the console and the station read --------------------------------------------------
    def pending(self) -> list[EpisodeTask]:
        """The drives still to do, in order: the warm-up first, then the trials without a part."""
        warm_up = [self.warm_up] if self.warm_up is not None and not self.warmed_up else []
        return warm_up + [task for task in self.tasks if not self.study.is_done(task)]

    def pending_questionnaire(self) -> tuple[str, str | None, Questionnaire] | None:
        """(placement, trial, questionnaire) of the next questionnaire to answer, or None: the
        `before` ones first, then the `after_each_trial` ones of each done trial, then the `end`
        ones once every trial is done (harness/live/answers.py)."""
        plan, study_dir, p = self.study.questionnaires, self.study.study_dir, self.participant
        asked: list[tuple[str, str | None, Questionnaire]] = [("before", None, q) for q in plan["before"]]
        asked += [("after_each_trial", task.episode_id, q) for task in self.tasks if self.study.is_done(task)
                  for q in plan["after_each_trial"]]
        if all(self.study.is_done(task) for task in self.tasks):
            asked += [("end", None, q) for q in plan["end"]]
        unanswered = (entry for entry in asked
                      if not answered(study_dir, p, entry[0], entry[1], entry[2].name))
        return next(unanswered, None)

    def next_phase(self) -> str:
        """After the consent or a drive: a questionnaire to answer, else a drive to start, else done."""
        if self.pending_questionnaire() is not None:
            return "questionnaire"
        return "ready" if self.pending() else "done"

    def progress(self) -> dict:
        with self.lock:
            done = [task.episode_id for task in self.tasks if self.study.is_done(task)]
            pending = self.pending()
            trial = self.trial_number(len(done))
            return {"type": "state", "participant": self.participant, "label": self.label,
                    "phase": self.phase, "paused_by": self.pause_reason, "trial": trial,
                    "warm_up": None if self.warm_up is None else ("done" if self.warmed_up else "pending"),
                    "trials": len(self.tasks), "trial_status": self.trial_status(trial),
                    "station": station_texts(self.phase, trial, len(self.tasks), self.warm_up_shown),
                    **self.drive_shown(), "done": done, "last_error": self.last_error,
                    "next_episode": pending[0].episode_id if pending else None,
                    "questionnaire": self.questionnaire_shown(),
                    "actions": list(CONSOLE_ACTIONS[self.console_phase()])}

    def trial_number(self, done: int) -> int:
        """The state's `trial`: the `done` trials, plus the one driven (not the warm-up)."""
        return done + (self.in_drive and not self.warming_up)

    @property
    def in_drive(self) -> bool:
        """A drive (the warm-up or a trial) runs, or is paused."""
        return self.phase in ("driving", "paused")

    @property
    def road(self) -> str | None:
        """The road the running drive's car is on (its newest frame's)."""
        return None if self.frame is None else self.frame["road"]

    @property
    def warm_up_shown(self) -> bool:
        """The drive under way (or paused), or between drives the next one, is the warm-up."""
        return self.warming_up if self.in_drive else self.warm_up is not None and not self.warmed_up

    def trial_status(self, trial: int) -> str:
        """Where the participant is among their trials, in words that cannot be misread: the trial
        driven ("driving 2 of 3", "paused in 2 of 3", or the warm-up), else how many are done ("1 of 3
        done"), whatever comes next."""
        if not self.in_drive:
            return f"{trial} of {len(self.tasks)} done"
        which = "the warm-up" if self.warming_up else f"{trial} of {len(self.tasks)}"
        return f"{'driving' if self.phase == 'driving' else 'paused in'} {which}"

    def drive_shown(self) -> dict:
        """The state's fields of the drive: its episode, road, reports and takeovers while one runs
        or is paused; all null between drives, where the drive that ended is no longer shown as if
        it were on. (The mode is the session's at any time: autopilot between drives.)"""
        shown = {"episode_id": self.task.episode_id if self.task else None, "road": self.road,
                 "reports": self.reports, "takeovers": self.takeovers}
        return {"mode": self.mode, **(shown if self.in_drive else dict.fromkeys(shown))}

    def opening(self) -> list[dict]:
        """What a station that connects is sent first: the state, and while the drive is paused
        (no frame streams then) the drive's newest frame, so that a station opened again during the
        pause shows where the car stands before the participant resumes."""
        with self.lock:
            frame = [self.frame] if self.phase == "paused" and self.frame is not None else []
            return [self.progress(), *frame]

    def console_phase(self) -> str:
        """The phase whose console actions the session accepts (CONSOLE_ACTIONS): its own, or for
        a paused episode "disconnected" (the participant's disconnect paused it) or "away" (the
        experimenter paused it, and no station is connected)."""
        if self.phase != "paused" or (self.pause_reason != "disconnect" and self.push is not None):
            return self.phase
        return "disconnected" if self.pause_reason == "disconnect" else "away"

    def questionnaire_shown(self) -> dict | None:
        """The questionnaire the station shows in phase "questionnaire" (with where it is asked)."""
        entry = self.pending_questionnaire() if self.phase == "questionnaire" else None
        if entry is None:
            return None
        placement, trial, questionnaire = entry
        return {**questionnaire.to_client(placement), "placement": placement, "trial": trial}

    # -- the participant's messages -------------------------------------------------------------
    def drive(self, message: Drive | Steer | Control) -> None:
        """Manual driving in control: the study's way of driving (a control by wheel, gamepad or
        keyboard only as `[live] inputs` allows), passed to the episode."""
        self.require("driving", message)
        config = self.study.config
        if isinstance(message, Control) != (config.live_driving == "continuous"):
            raise MessageError("out_of_order", f"{message.type} is not how this study drives")
        if isinstance(message, Control) and message.source not in config.live_inputs:
            raise MessageError("out_of_order", f"this study does not allow driving by {message.source}")
        if self.mode != "manual":
            raise MessageError("out_of_order", f"{message.type} while the mode is {self.mode}")
        self.tell(message.model_dump())

    def handle(self, message: ClientMessage) -> list[dict]:
        """Apply a validated client message; its replies. MessageError when out of order."""
        with self.lock:
            if isinstance(message, (Ping, Shown)):
                return self.signal(message)
            if isinstance(message, Consent):
                self.require("consent", message)
                if not message.agree:
                    self.phase, self.label = "declined", ""   # (the registry keeps no label either)
                    self.study.decline(self.participant)
                    return [self.progress()]
                self.client, self.lockstep = message.client, message.lockstep
                self.phase = self.next_phase()
                self.study.save_participants()   # the consent holds across restarts
            elif isinstance(message, Start):
                self.require("ready", message)
                self.start(self.pending()[0], message.trust)
            elif isinstance(message, (Takeover, HandBack)):
                return self.switch(message)
            elif isinstance(message, (Drive, Steer, Control)):
                self.drive(message)
                return []
            elif isinstance(message, Pass):
                self.require("driving", message)
                if not self.lockstep:
                    raise MessageError("out_of_order", "pass answers an incident in lockstep only")
                self.tell(message.model_dump())
                return []
            elif isinstance(message, TrustReport):
                self.report(message)
                return [Reported(value=message.value, prompt=message.prompt).model_dump()]
            elif isinstance(message, Answers):
                self.require("questionnaire", message)
                self.answer(message)
            elif isinstance(message, Resume):
                self.require("paused", message)
                if self.pause_reason != "disconnect":
                    raise MessageError("out_of_order", "the experimenter paused this episode")
                self.resume()
            return [self.progress()]

    def switch(self, message: Takeover | HandBack) -> list[dict]:
        """A takeover or hand-back, told to the episode (its `mode` event confirms it). One asking
        for the mode the episode switched to on its own since the participant last asked is done
        already: the junction's hand-back, or the drive's end (which takes the car from a person in
        control, `end_drive`), crossed by a hand-back sent a moment late. The state acknowledges it
        and no episode is told, so nothing is logged. Any other asking for the mode the ego is on,
        or coming outside a drive, is out of order: a second request, one before its first is
        applied, a hand-back on autopilot."""
        wanted = REQUESTED_MODE[message.type]
        if self.mode == wanted and self.switched_unasked:
            self.switched_unasked = False   # (asked for now: a second request is out of order)
            return [self.progress()]
        self.require("driving", message)
        if self.mode == wanted:
            raise MessageError("out_of_order", f"{message.type} while the mode is {self.mode}")
        self.tell(message.model_dump())
        self.asked, self.switched_unasked = wanted, False
        return []

    def signal(self, message: Ping | Shown) -> list[dict]:
        """A ping's pong; the station's `shown` to the running episode, for its pace (no reply)."""
        if isinstance(message, Ping):
            return [{"type": "pong"}]
        if self.phase == "driving":
            with contextlib.suppress(MessageError):   # (the episode has just ended)
                self.tell(message.model_dump())
        return []

    def report(self, message: TrustReport) -> None:
        """A trust report to the running episode (answering a prompt of this episode, or none)."""
        self.require("driving", message)
        prompt = message.prompt
        if prompt is not None and (self.task is None or prompt.episode_id != self.task.episode_id):
            raise MessageError("out_of_order", "the report answers a prompt of another episode")
        if prompt is not None and prompt.road not in self.prompted:
            raise MessageError("out_of_order", f"no report has been asked about road {prompt.road}")
        self.tell(message.model_dump())
        self.reports += 1

    def answer(self, message: Answers) -> None:
        """The participant's answers to the questionnaire shown: checked, saved, on to the next phase."""
        pending = self.pending_questionnaire()
        if pending is None:
            raise MessageError("out_of_order", "no questionnaire is shown")
        placement, trial, questionnaire = pending
        if message.questionnaire != questionnaire.name:
            raise MessageError("out_of_order", f"the questionnaire shown is {questionnaire.name}")
        try:
            answers = questionnaire.check(message.answers)
        except ValueError as exc:
            raise MessageError("malformed", str(exc)) from None
        save_answers(self.study.study_dir, self.participant, placement, trial, questionnaire, answers)
        self.phase = self.next_phase()

    def require(self, phase: str, message: ClientMessage) -> None:
        if self.phase != phase:
            raise MessageError("out_of_order", f"{message.type} in phase {self.phase!r} (needs {phase!r})")

    # -- the episode ----------------------------------------------------------------------------
    @property
    def warming_up(self) -> bool:
        return self.task is not None and self.task is self.warm_up

    def start(self, task: EpisodeTask, trust: int | None) -> None:
        target = self.study.warm_up_dir() if task is self.warm_up else self.study.study_dir
        self.process, self.connection = start_episode_process(
            self.study.config, target, task, self.study.live_options(self.client, self.lockstep), trust)
        self.task, self.phase, self.mode, self.frame, self.last_error = task, "driving", "auto", None, None
        self.asked, self.switched_unasked = "auto", False
        self.prompted = set()
        self.reports = self.takeovers = 0   # the console shows them beside this drive's episode
        self.study.attempt_started(task, task is self.warm_up)
        reader = threading.Thread(target=self.read_episode, args=(self.connection, self.process),
                                  name=f"live-reader-{task.episode_id}", daemon=True)
        reader.start()

    def read_episode(self, connection, process) -> None:
        """The reader thread: every message of the episode process, until its pipe closes."""
        ended = False
        while True:
            try:
                message = connection.recv()
            except (EOFError, OSError):
                break
            ended |= message.get("type", "") in ("episode_end", "episode_aborted", "episode_failed")
            self.on_episode_message(message)
        process.join(STOP_SECONDS)
        if not ended:
            self.on_episode_message({"type": "episode_failed",
                                     "error": f"the episode process ended (exit code {process.exitcode})"})

    def on_episode_message(self, message: dict) -> None:
        kind = message.get("type")
        finished = kind in ("episode_end", "episode_aborted", "episode_failed")
        shown = {key: value for key, value in message.items() if key != "traceback"}   # the station's
        with self.lock:
            if self.phase == "withdrawn":
                return   # withdrawn: nothing of this episode is kept, nothing is sent
            if kind == "mode":
                self.mode = message["mode"]
                self.takeovers += self.mode == "manual"
                self.switched_unasked = self.mode != self.asked
            elif kind == "warning" and message.get("kind") == "back_to_lane":
                self.asked = self.mode   # the episode refused the hand-back (by wheel, off the lane)
            elif kind == "frame":
                self.frame = message
            elif kind == "road" and message.get("prompt"):   # (recorded before the station sees it)
                self.prompted.add(int(message["prompt"]["road"]))
            elif finished:
                done = sum(self.study.is_done(task) for task in self.tasks)
                said = station_end(message, self.trial_number(done), len(self.tasks), self.warming_up)
                shown = {**shown, "station": said}
                self.study.attempt_ended(self.task, message)
                if kind == "episode_end" and self.warming_up:
                    self.warmed_up = True
                    self.study.save_participants()
                elif kind == "episode_end":
                    self.study.episode_finished(self.task)
                else:
                    self.last_error = message.get("error") or message.get("reason")
                self.end_drive()
                self.phase = self.next_phase()
                self.pause_reason, self.process, self.connection, self.frame = None, None, None, None
                if self.expiry is not None:
                    self.expiry.cancel()
                    self.expiry = None
            push = self.push
        if push is not None:
            push(shown)
            if finished:
                push(self.progress())

    def end_drive(self) -> None:
        """The drive is over, however it ended: the car is no longer the person's. Had they taken
        over (or asked to), the end hands back on its own, so a hand-back sent as it ended is done
        already (`switch`)."""
        self.mode, self.switched_unasked = AUTOPILOT.name, self.asked != AUTOPILOT.name

    def control(self, action: str) -> dict:
        """The experimenter's pause, resume or abort of the running episode. A pause or resume is
        pushed to the station too: the participant must see why the view stands still, and when
        it goes on (an abort is told by the episode's own `episode_aborted`)."""
        with self.lock:
            refusal = console_refusal(self.participant, self.console_phase(), action)
            if refusal is not None:
                raise MessageError("out_of_order", refusal)
            if action == "pause":
                self.pause("experimenter")
            elif action == "resume":
                self.resume()
            else:
                self.tell({"type": "abort", "reason": "aborted by the experimenter"})
            progress, push = self.progress(), self.push
        if push is not None and action != "abort":
            push(progress)
        return progress

    def tell(self, control: dict) -> None:
        """Send a control to the running episode (MessageError when it has just ended)."""
        try:
            self.connection.send(control)
        except (OSError, ValueError, AttributeError):
            raise MessageError("out_of_order", "the episode has ended") from None

    def pause(self, reason: str) -> None:
        self.tell({"type": "pause"})
        self.phase, self.pause_reason = "paused", reason
        if reason == "disconnect":
            self.expiry = threading.Timer(self.study.options.resume_within, self.expire, args=(self.task,))
            self.expiry.daemon = True
            self.expiry.start()

    def resume(self) -> None:
        self.tell({"type": "resume"})
        self.phase, self.pause_reason = "driving", None
        if self.expiry is not None:
            self.expiry.cancel()
            self.expiry = None

    def expire(self, task: EpisodeTask) -> None:
        """The participant did not come back in time: the episode is incomplete (no part) and its
        trial moves to the end of the participant's plan."""
        with self.lock:
            if self.phase != "paused" or self.pause_reason != "disconnect" or self.task is not task:
                return
            self.expiry = None
            with contextlib.suppress(MessageError):
                self.tell({"type": "abort", "reason": f"incomplete: no reconnection within "
                                                      f"{self.study.options.resume_within:g} s"})
            if task in self.tasks:   # (a warm-up simply stays first)
                self.tasks.remove(task)
                self.tasks.append(task)
                self.study.save_participants()   # the new order holds across restarts

    # -- the participant's connection -----------------------------------------------------------
    def attach(self, push: Callable[[dict], None]) -> tuple[Callable[[dict], None] | None, list[dict]]:
        """The participant's connection opened: the one it replaces (None if none: one window holds
        the session at a time), and what it is sent first (`opening`), read in the lock section
        that gives it the episode's messages, so that none it is pushed (an `episode_end`) comes
        before a state older than it."""
        with self.lock:
            previous, self.push = self.push, push
            return previous, self.opening()

    def detach(self, push: Callable[[dict], None]) -> None:
        """The participant's connection closed: a running episode pauses until they resume."""
        with self.lock:
            if self.push is not push:
                return
            self.push = None
            if self.phase == "driving":
                with contextlib.suppress(MessageError):   # the episode ended meanwhile
                    self.pause("disconnect")

    def stop(self) -> None:
        """Stop a running episode (the server is closing): no part is written for it."""
        with self.lock:
            process = self.process
        if process is not None:
            process.terminate()
            process.join(STOP_SECONDS)
            if process.is_alive():
                process.kill()
