"""The live study's directory and participants: the one object the web application serves.

`LiveStudy.open()` does what `trustroute study` does before it writes anything (every input
validated and the "aware" policies synthesized: `validate_study`; the study's context it builds
is held as `LiveStudy.context`, for the expected values, every consolidation and the station's
view of the net) and takes the study directory as `trustroute study` does (`open_study_dir`: a
folder that is neither new, empty nor this study's is refused; the directory is marked as this
config's first, then locked, so a second server, or a `trustroute study`, on it is refused with
the holder named). The directory then holds, besides a study's files,

    live/participants.json   each created participant: SHA-256 of their token, label, consent,
                             whether the warm-up drive is done
    live/warmup/parts/       the warm-up drives' parts (not part of the dataset)

and after every finished episode the dataset is consolidated (harness/study/manifest.py) so
`trustroute analyze` reads the directory at any time. harness/live/app.py serves it.
"""

from __future__ import annotations

import contextlib
import json
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

from trustroute.app.engines import ENGINES
from trustroute.app.nets import net_for
from trustroute.core import defaults
from trustroute.core.dataset import part_path
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_text
from trustroute.core.ranges import CONNECTIONS_PER_ADDRESS, PACE, RESUME_WITHIN, keep_checked
from trustroute.harness.live.attempts import AttemptLog
from trustroute.harness.live.auth import Credentials, experimenter_credentials
from trustroute.harness.live.session import Session, console_refusal
from trustroute.harness.live.warmup import WARM_UP_KEY  # SeedSequence(study seed, (4, participant))
from trustroute.harness.live.withdraw import (
    ENDED,
    load_registry,
    read_registry,
    read_withdrawal,
    withdraw_participant,
)
from trustroute.harness.live.worker import FINAL_REPORT_SECONDS, LiveOptions, start_fork_server
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.context import StudyContext
from trustroute.harness.study.plan import EpisodeTask, plan_episodes
from trustroute.participants.questionnaires import questionnaire_plan

LIVE_DIR = "live"
PARTICIPANTS_FILE = "participants.json"
WARM_UP_DIR = "warmup"
TOKEN_LOG = "tokens.jsonl"     # every token replaced: when, whose, why
CONSENT_FILE = "consent.txt"   # the consent text participants are shown
DEFAULT_CONSENT = ("You are about to drive in a simulated study of an autonomous vehicle. You may take over "
                   "and hand back control, and report your trust in the vehicle from 1 to 7. You may stop "
                   "at any time.")
MAX_DOWNLOAD_PATH = 512
SPENT_LINK = "this link is spent or revoked; ask the experimenter for a new one"


@dataclass(frozen=True)
class ServerOptions:
    pace: float = defaults.LIVE_PACE
    frame_rate: float = 25.0
    resume_within: float = defaults.LIVE_RESUME_WITHIN   # seconds a disconnected participant has to resume
    warm_up: bool = defaults.LIVE_WARM_UP   # a warm-up drive before the trials
    secure_cookies: bool = False   # cookies only over HTTPS (behind a TLS proxy)
    final_report_seconds: float = FINAL_REPORT_SECONDS   # a trial's end waits this for the last report
    public_origins: tuple[str, ...] = ()   # the origins the study is reached at behind a proxy
    idle_seconds: float = 60.0     # a websocket silent this long is closed (the station pings)
    request_seconds: float = 10.0  # an HTTP request not complete this long after it began is cut
    max_connections: int | None = None   # open at once (None: sized for the study, guard.connection_cap)
    connections_per_address: int | None = None   # of those, from one address (None: guard.address_cap)

    def __post_init__(self) -> None:
        """The pace, the resume window and one address's cap as `trustroute live` takes them (the
        ranges both check)."""
        keep_checked(self, {"pace": PACE, "resume_within": RESUME_WITHIN,
                            "connections_per_address": CONNECTIONS_PER_ADDRESS},
                     optional=("connections_per_address",))


def warm_up_task(config: StudyConfig, participant: int) -> EpisodeTask:
    """The participant's warm-up drive: their first trial's spec, condition and driver on seeds of
    its own, driven on a route and incidents of its own (harness/live/warmup.py); it is not part of
    the dataset."""
    import numpy as np

    first = min((t for t in plan_episodes(config) if t.participant == participant), key=lambda t: t.position)
    sequence = np.random.SeedSequence(config.seed, spawn_key=(WARM_UP_KEY, participant))
    return replace(first, episode_id=f"p{participant:05d}-warmup", position=-1,
                   seed=int(sequence.generate_state(1)[0] & 0x7FFFFFFF),
                   driver_entropy=(config.seed, WARM_UP_KEY, participant))


class LiveStudy:
    """A study served live: config, directory (locked while open), credentials, sessions."""

    def __init__(self, config: StudyConfig, study_dir: Path, options: ServerOptions | None = None,
                 consent_text: str = DEFAULT_CONSENT) -> None:
        if ENGINES[config.engine].synthetic:   # a simulated engine: `trustroute study` runs it
            raise InputError(config.source_path, "study.engine",
                             f"engine {config.engine!r} is not served live",
                             'set engine = "live" (or run `trustroute study` for a simulated study)')
        self.config = config
        self.study_dir = Path(study_dir).resolve()
        self.options = options or ServerOptions()
        self.consent_text = consent_text
        self.tasks = plan_episodes(config)
        self.credentials: Credentials
        self.credentials, self.experimenter_token = experimenter_credentials()
        self.login_token = self.credentials.new_login()   # the console link printed at start
        self.sessions: dict[int, Session] = {}
        self.done: set[str] = set()
        # The study's lock guards the registry, the journal and the dataset. Lock order: a
        # session's lock (harness/live/session.py) may be held when the study's is taken (a
        # consent saves the registry, a start journals its attempt, an episode's end consolidates,
        # a token's issue and a withdrawal's start hold both), never the other way round: no code
        # holding the study's lock takes a session's.
        self.lock = threading.RLock()
        self.expected: dict = {}
        self.context: StudyContext   # the study's context, built by `open` (`check_before_writing`)
        self.attempts = AttemptLog(self.study_dir, LIVE_DIR)
        self.questionnaires = questionnaire_plan(config.questionnaires, Path(config.source_path).parent,
                                                 config.source_path)
        self.withdrawn: dict[int, dict] = {}   # participant -> their registry record once withdrawn
        self.declined: dict[int, dict] = {}    # participant -> their registry record once declined
        self._stack = contextlib.ExitStack()

    # -- opening and closing --------------------------------------------------------------------
    def open(self) -> LiveStudy:
        from trustroute.harness.study.expected import expected_values
        from trustroute.harness.study.resume import finished_episodes
        from trustroute.harness.study.runner import check_before_writing, open_study_dir

        self.context = check_before_writing(self.config, self.study_dir, None, defaults.ATTEMPTS, False)
        self._stack.enter_context(open_study_dir(self.study_dir, self.config))
        try:
            # it imports the episodes' modules while the study opens: the opening's slowest step,
            # where a SIGTERM or Ctrl-C most likely lands, so inside what lets the directory go
            start_fork_server()
            self.done = finished_episodes(self.study_dir, self.tasks)[0]
            self.expected = expected_values(self.context)
            self.load_participants()
            atomic_write_text(self.study_dir / LIVE_DIR / CONSENT_FILE, self.consent_text,
                              "the consent text shown", "free disk space")   # exported with the data
        except BaseException:
            self._stack.close()
            raise
        return self

    def close(self) -> None:
        for session in list(self.sessions.values()):
            session.stop()
        self._stack.close()

    def __enter__(self) -> LiveStudy:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- participants ---------------------------------------------------------------------------
    def registry_path(self) -> Path:
        return self.study_dir / LIVE_DIR / PARTICIPANTS_FILE

    def load_participants(self) -> None:
        path = self.registry_path()
        if not path.exists():
            return
        records = load_registry(path, "restore it, or delete the study directory")
        for key, record in records["participants"].items():
            participant = int(key)
            # withdrawn (harness/live/withdraw.py) or declined (`decline`): no data, no token
            ended = next((phase for phase in ENDED if record.get(phase)), None)
            if ended is not None:
                (self.withdrawn if ended == "withdrawn" else self.declined)[participant] = record
                self.sessions[participant] = self.new_session(participant)
                self.sessions[participant].phase = ended
                continue
            if record.get("digest"):   # (none after a readmission, until the console issues a link)
                self.credentials.participants[participant] = str(record["digest"])
            self.sessions[participant] = self.new_session(participant, str(record.get("label", "")),
                                                          bool(record.get("consented")),
                                                          str(record.get("client", "station")),
                                                          bool(record.get("warmed_up")),
                                                          list(record.get("order", [])))
            self.sessions[participant].lockstep = bool(record.get("lockstep"))

    def save_participants(self) -> None:
        with self.lock:
            records = {str(p): self.withdrawn.get(p) or self.declined.get(p) or
                       {"digest": self.credentials.participants.get(p), "label": s.label,
                        "consented": s.phase != "consent", "client": s.client,
                        "warmed_up": s.warmed_up, "lockstep": s.lockstep,
                        "order": [task.episode_id for task in s.tasks]}
                       for p, s in sorted(self.sessions.items())}
            atomic_write_text(self.registry_path(), json.dumps({"participants": records}, indent=1),
                              "live participants", "free disk space")

    def tasks_of(self, participant: int) -> list[EpisodeTask]:
        return sorted((t for t in self.tasks if t.participant == participant), key=lambda t: t.position)

    def new_session(self, participant: int, label: str = "", consented: bool = False,
                    client: str = "station", warmed_up: bool = False,
                    order: list[str] | None = None) -> Session:
        """The participant's session; `order`: their trials' episode ids in the order to run (the
        plan's, with incomplete trials moved to the end), kept across restarts."""
        warm_up = warm_up_task(self.config, participant) if self.options.warm_up else None
        tasks = self.tasks_of(participant)
        if order:
            place = {episode: i for i, episode in enumerate(order)}
            tasks.sort(key=lambda task: place.get(task.episode_id, len(place)))
        return Session(self, participant, tasks, label, consented, client, warm_up=warm_up,
                       warmed_up=warmed_up)

    def create_participant(self, label: str = "") -> tuple[int, str]:
        """(index, token) of the next participant of the plan; ValueError when all exist."""
        with self.lock:
            participant = len(self.sessions)
            if participant >= self.config.participants:
                raise ValueError(f"the study plans {self.config.participants} participants; all are created")
            token = self.credentials.add_participant(participant)
            self.sessions[participant] = self.new_session(participant, label)
            self.save_participants()
            return participant, token

    def replace_token(self, participant: int, reason: str, spent: str | None = None) -> str:
        """A fresh token for `participant`, the previous one revoked; logged (time, participant,
        reason) in live/tokens.jsonl. ValueError, and no token, once their withdrawal has begun,
        or when `spent` (the token of the link being claimed) is no longer theirs: spent by
        another claim, or revoked. A token is issued, and a withdrawal begins (`withdraw`), under
        the participant's session lock and then the study's, so neither comes between the
        other's check and its change."""
        session = self.sessions[participant]
        with session.lock, self.lock:
            refusal = console_refusal(participant, session.console_phase(), "link")
            if refusal is not None:
                raise ValueError(refusal)
            if spent is not None and self.credentials.participant_of(spent) != participant:
                raise ValueError(SPENT_LINK)
            token = self.credentials.add_participant(participant)
            self.save_participants()
            log = self.study_dir / LIVE_DIR / TOKEN_LOG
            with log.open("a", encoding="utf-8") as out:
                out.write(json.dumps({"utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                      "participant": participant, "event": reason}) + "\n")
            return token

    def claim_link(self, token: str) -> tuple[int, str]:
        """(participant, fresh token) for the token of a participant's link opened in a browser
        (the link spent); ValueError when it is no participant's token now, or they have withdrawn."""
        participant = self.credentials.participant_of(token)
        if participant is None:
            raise ValueError(SPENT_LINK)
        return participant, self.replace_token(participant, "link opened in a browser", spent=token)

    def login(self, token: str | None) -> str | None:
        """The console session token a login link's `token` is exchanged for (the link spent), or
        None when it is no unspent login token."""
        with self.lock:
            return self.credentials.spend_login(token)

    def new_login_link(self) -> str:
        """A fresh one-time login token (an unspent earlier one no longer logs in)."""
        with self.lock:
            return self.credentials.new_login()

    def decline(self, participant: int) -> None:
        """`participant` did not agree to take part (their session's phase is "declined"): as after
        a withdrawal, their registry record keeps only that and its time (no label, no token, so
        their link and cookie open nothing), and nothing else of theirs exists (the consent comes
        before any drive or answer). Their index is not reused; a new link from the console asks
        for their consent again (`ask_again`)."""
        with self.lock:
            self.credentials.participants.pop(participant, None)
            self.declined[participant] = {"declined": True,
                                          "declined_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
            self.save_participants()

    def ask_again(self, participant: int) -> None:
        """A participant who declined is asked for their consent again (with the new link the
        console makes next: they may have changed their mind, or pressed the wrong button)."""
        session = self.sessions[participant]
        with session.lock:   # not inside the study's lock (the lock order: LiveStudy.lock)
            session.phase = "consent"
        with self.lock:
            self.declined.pop(participant, None)

    def withdraw(self, participant: int, reason: str = "") -> dict:
        """The experimenter withdraws `participant` (harness/live/withdraw.py): their episode
        stopped, their data removed and the dataset consolidated without them; the audit entry.
        ValueError when there is no such participant or they have withdrawn already, or (one line,
        the participant left as they were) when a file the withdrawal reads (the registry, the
        manifest and the study's inputs, the journal, the answers, the export key) cannot be read."""
        session = self.sessions.get(participant)
        refusal = f"participant {participant} does not exist or has withdrawn already"
        if session is None:
            raise ValueError(refusal)
        with session.lock, self.lock:   # the withdrawal begins: no token is issued after it (replace_token)
            # (checked under the locks a decline and a withdrawal take too)
            refused = console_refusal(participant, session.console_phase(), "withdraw")
            if refused is not None:
                raise ValueError(refused)
            try:   # everything the withdrawal reads, checked before the session ends: a file that
                read_withdrawal(self.study_dir, participant)   # cannot be read leaves it as it was
            except InputError as exc:   # (all read again by the withdrawal, as they are then)
                raise ValueError(exc.one_line()) from None
            session.phase = "withdrawn"   # the episode's last message changes nothing now
            session.label = ""            # (the registry keeps none either)
            self.credentials.participants.pop(participant, None)   # their token revoked
            self.save_participants()
        session.stop()
        with self.lock:
            try:
                entry = withdraw_participant(self.study_dir, participant, "experimenter (console)", reason)
            except InputError as exc:
                raise ValueError(exc.one_line()) from None
            self.withdrawn[participant] = read_registry(self.study_dir)["participants"][str(participant)]
            self.done -= {task.episode_id for task in self.tasks_of(participant)}
            return entry

    def warm_up_dir(self) -> Path:
        return self.study_dir / LIVE_DIR / WARM_UP_DIR

    # -- episodes -------------------------------------------------------------------------------
    def is_done(self, task: EpisodeTask) -> bool:
        return task.episode_id in self.done

    def live_options(self, client: str, lockstep: bool = False) -> LiveOptions:
        return LiveOptions(self.options.pace, self.options.frame_rate, client, self.config.report_every,
                           lockstep, self.options.final_report_seconds, self.config.live_driving)

    def attempt_started(self, task: EpisodeTask, warm_up: bool) -> None:
        with self.lock:
            self.attempts.started(task, warm_up)
            self.attempts.write()

    def attempt_ended(self, task: EpisodeTask, message: dict) -> None:
        """An attempt ended (done, aborted, failed, incomplete): journalled, attempts.parquet rewritten."""
        with self.lock:
            self.attempts.ended(task, message)
            self.attempts.write()

    def episode_finished(self, task: EpisodeTask) -> None:
        """An episode wrote its part: count it done and consolidate the dataset."""
        from trustroute.harness.study.manifest import consolidate

        with self.lock:
            if part_path(self.study_dir, task.episode_id).exists():
                self.done.add(task.episode_id)
            consolidate(self.study_dir, self.context, self.tasks, self.config.content_hash, self.expected,
                        {"backend": "live", "pace": self.options.pace, "finished_utc":
                         time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})

    def net_view(self) -> dict:
        """The lanes of the net the study's town drives (`net_for`: an imported town's own net), for
    the station's view (harness/live/view.py)."""
        from trustroute.harness.live.view import net_view

        return net_view(str(net_for(self.context.town)))

    # -- downloads ------------------------------------------------------------------------------
    def files(self) -> list[str]:
        """Every regular file of the study directory (relative paths), the lock excepted."""
        from trustroute.core.dataset import LOCK_FILE

        return sorted(str(path.relative_to(self.study_dir)) for path in self.study_dir.rglob("*")
                      if path.is_file() and not path.is_symlink() and path.name != LOCK_FILE)

    def download_path(self, relative: str) -> Path:
        """The file `relative` names inside the study directory; ValueError for any path that
        leaves it (.., an absolute path, a symlink anywhere on the way) or is not a regular file."""
        root = self.study_dir
        if not relative or len(relative) > MAX_DOWNLOAD_PATH or "\x00" in relative or "\\" in relative:
            raise ValueError("not a file of the study directory")
        parts = Path(relative).parts
        if Path(relative).is_absolute() or any(part in ("..", ".") for part in parts):
            raise ValueError("not a file of the study directory")
        current = root
        for part in parts:
            current = current / part
            if current.is_symlink():
                raise ValueError("not a file of the study directory")
        resolved = current.resolve()
        if not resolved.is_relative_to(root) or not resolved.is_file():
            raise ValueError("not a file of the study directory")
        return resolved

