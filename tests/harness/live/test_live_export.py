"""`trustroute export` of a live study, read back: every column of every table agrees with its
codebook entry (type, nulls, allowed values), the participants are pseudonymous, the rows follow the
pseudonyms and no wall-clock time is left, the README reports the participant flow (withdrawals
counted), and the checksums hold."""

from __future__ import annotations

import hashlib
import json
import re
from datetime import datetime

import pyarrow.parquet as pq
import pytest

from tests.cli import assert_one_line_error, run_cli
from tests.export_checks import (
    assert_no_wall_clock,
    assert_nothing_identifying,
    assert_rows_in_code_order,
    assert_task_inputs,
    package_key,
)
from tests.questionnaire_files import COMFORT
from trustroute.core.codebook import type_name
from trustroute.harness.live.scripted import ScriptedParticipant, run_scripted
from trustroute.harness.live.server import DEFAULT_CONSENT, LiveStudy, ServerOptions
from trustroute.harness.study.export import read_export_keys

from .conftest import TINY, serving, tiny_config

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]
WORDS = re.compile(r"^[a-z_]+(, [a-z_]+)+$")


def check_column(values: list, entry: dict) -> None:
    present = [value for value in values if value is not None]
    assert entry["nullable"] or len(present) == len(values), entry["column"]
    allowed = entry["allowed"]
    if WORDS.match(allowed):
        assert {str(v).lower() for v in present} <= set(allowed.split(", ")), (entry["column"], set(present))
    elif allowed.startswith("integers 1-7"):
        assert all(1 <= v <= 7 for v in present), entry["column"]
    elif allowed.startswith("integers >= "):   # the range, before any value of an imported study
        assert all(v >= int(allowed.split(";")[0].rsplit(" ", 1)[1]) for v in present), entry["column"]
    elif allowed == ">= 0":
        assert all(v >= 0 for v in present), entry["column"]


def check_seconds(package, study_dir, key: dict[int, int]) -> None:
    """The attempts' times are seconds since each participant's first (0), with the study's durations."""
    exported = pq.read_table(package / "tables" / "attempts.parquet").to_pylist()
    study = pq.read_table(study_dir / "attempts.parquet").to_pylist()
    for p, code in key.items():
        mine = [row for row in study if row["participant"] == int(p)]
        theirs = [row for row in exported if row["participant"] == code]
        assert min(row["started_s"] for row in theirs) == 0
        for row, original in zip(theirs, mine, strict=True):
            start, end = (datetime.fromisoformat(original[c]) for c in ("started_utc", "ended_utc"))
            assert row["ended_s"] - row["started_s"] == (end - start).total_seconds() >= 0


def drive_two(tmp_path, planned: int, consent_text: str = DEFAULT_CONSENT):
    """A live study of `planned` participants of whom the first two drive every trial (scripted);
    its directory and the package's path."""
    config = tiny_config(tmp_path, participants=planned)
    study_dir, package = tmp_path / "study", tmp_path / "package"
    study = LiveStudy(config, study_dir, ServerOptions(pace=1000.0), consent_text=consent_text).open()
    try:
        with serving(study) as (host, port):
            for p in range(2):
                token = study.create_participant()[1]
                run_scripted(f"ws://{host}:{port}/ws", token, ScriptedParticipant(config, p), 120)
    finally:
        study.close()
    return study_dir, package


def test_an_exported_live_study_reads_back_against_its_codebook(tmp_path, capsys):
    study_dir, package = drive_two(tmp_path, 2, consent_text="Consent: drive.")
    code, out, err = run_cli(capsys, "export", str(study_dir), "--out", str(package), "--seed", "5")
    assert code == 0, err
    book = json.loads((package / "codebook.json").read_text())
    assert {"episodes", "roads", "kinematics", "attempts"} <= set(book)
    for table, entries in book.items():
        data = pq.read_table(package / "tables" / entries[0]["file"])
        assert data.schema.names == [entry["column"] for entry in entries], table
        for entry in entries:
            field = data.schema.field(entry["column"])
            assert type_name(field.type) == entry["type"], (table, entry["column"])
            check_column(data.column(entry["column"]).to_pylist(), entry)
        if "participant" in data.schema.names:
            assert all(100 <= p <= 999 for p in data.column("participant").to_pylist())
        if "episode_id" in data.schema.names:
            episodes = data.column("episode_id").to_pylist()
            assert not any(e.startswith(("p00000-", "p00001-")) for e in episodes)
    key = package_key(study_dir, package)
    assert sorted(key) == [0, 1] and len(set(key.values())) == 2
    assert key[0] > key[1]   # seed 5: code order is not enrolment order, so the check below tells
    assert_rows_in_code_order(package, study_dir)
    assert_no_wall_clock(package)
    check_seconds(package, study_dir, key)
    assert (package / "texts" / "consent.txt").read_text() == "Consent: drive."
    exported_config = json.loads((package / "study_config.json").read_text())
    assert exported_config["name"] == "tiny-live"
    # the seeds, drawn from the study's seed and each participant's number, would give the codes'
    # numbers back: a study with people exports neither (the codebook check above saw the columns)
    assert "seed" in json.loads((study_dir / "manifest.json").read_text())["config"]
    assert "seed" not in exported_config
    assert "seed" not in pq.read_schema(package / "tables" / "episodes.parquet").names
    assert "seed" in pq.read_schema(study_dir / "episodes.parquet").names
    assert "packages" in json.loads((package / "versions.json").read_text())
    assert "pseudonymous" in (package / "README.md").read_text()
    sums = (package / "SHA256SUMS").read_text().splitlines()
    listed = {line.split("  ", 1)[1]: line.split("  ", 1)[0] for line in sums}
    files = {str(path.relative_to(package)) for path in package.rglob("*") if path.is_file()} - {"SHA256SUMS"}
    assert set(listed) == files
    for name, digest in listed.items():
        assert hashlib.sha256((package / name).read_bytes()).hexdigest() == digest, name
    assert not any("participants.json" in name or "tokens" in name for name in files)
    readme = (package / "README.md").read_text()
    assert "Participants: 2 planned, 2 with data in this package, 0 withdrawn" in readme
    assert "0 did not take part" in readme
    code, _, err = run_cli(capsys, "export", str(study_dir), "--out", str(package))
    assert code == 2 and f"lies in the package {package}" in err   # published read-only
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "notes.txt").write_text("kept")
    code, _, err = run_cli(capsys, "export", str(study_dir), "--out", str(tmp_path / "taken"))
    assert code == 2 and "not empty" in err and (tmp_path / "taken" / "notes.txt").read_text() == "kept"
    # re-analysed from its package, the study gives its own figures, field by field (the order of
    # its runs read from the package's attempts, its participants under their codes)
    own, packaged = (analyzed(capsys, folder) for folder in (study_dir, package))
    assert own["cells"] and own["order"]   # figures, not empty tables
    assert {k: v for k, v in packaged.items() if k != "study_dir"} == {
        k: v for k, v in own.items() if k != "study_dir"}


def analyzed(capsys, folder) -> dict:
    code, out, err = run_cli(capsys, "analyze", str(folder), "--json")
    assert code == 0, err
    return json.loads(out)


def test_the_package_says_what_each_questionnaire_asked_and_names_no_file_of_the_lab(tmp_path, capsys):
    """The questionnaires table holds item ids and values: the package carries the texts the
    participants answered (instructions where asked, the scale, each item and whether it is
    reversed), from the study's own copy of a questionnaire file, which may be gone from the lab's
    folder by then; and the exported config names the copy, not the file's place on the lab's disk."""
    from trustroute.harness.study.config import load_study_config

    lab = tmp_path / "lab-folder"
    lab.mkdir()
    (lab / "comfort.toml").write_text(COMFORT)
    path = lab / "live.toml"
    path.write_text(TINY.format(participants=1, specs='["phi1"]')
                    + '\n[questionnaires]\nafter_each_trial = ["jian"]\nend = ["comfort.toml"]\n')
    config = load_study_config(path)
    study_dir, package = tmp_path / "study", tmp_path / "package"
    study = LiveStudy(config, study_dir, ServerOptions(pace=1000.0)).open()
    try:
        with serving(study) as (host, port):
            token = study.create_participant()[1]
            run_scripted(f"ws://{host}:{port}/ws", token, ScriptedParticipant(config, 0), 120)
    finally:
        study.close()
    (lab / "comfort.toml").unlink()
    code, _, err = run_cli(capsys, "export", str(study_dir), "--out", str(package))
    assert code == 0, err
    shown = json.loads((package / "texts" / "questionnaires.json").read_text())
    assert [q["name"] for q in shown["after_each_trial"]] == ["jian"] and shown["before"] == []
    (comfort,) = shown["end"]
    assert comfort["instructions"] == "How much do you agree?"
    assert comfort["scale"] == {"min": 1, "max": 5, "step": 1, "low": "strongly disagree",
                                "high": "strongly agree"}
    assert [(i["id"], i["text"], i["reversed"]) for i in comfort["items"]] == [
        ("c1", "The ride felt smooth.", False), ("c2", "The ride felt jerky.", True)]
    answered = set(pq.read_table(package / "tables" / "questionnaires.parquet").column("item").to_pylist())
    assert answered == {i["id"] for q in shown["after_each_trial"] + shown["end"] for i in q["items"]}
    assert "questionnaires.json" in (package / "README.md").read_text()
    assert_no_wall_clock(package)
    answered = pq.read_table(package / "tables" / "questionnaires.parquet").column("answered_s").to_pylist()
    started = pq.read_table(package / "tables" / "attempts.parquet").column("started_s").to_pylist()
    assert min(answered + started) == 0 and max(answered) >= max(started)   # the end questionnaire is last
    assert str(tmp_path) not in (package / "study_config.json").read_text()
    # a questionnaire that cannot be read: one line, and no package begun
    (copy,) = (study_dir / "inputs").glob("*/comfort.toml")
    copy.unlink()
    code, _, err = run_cli(capsys, "export", str(study_dir), "--out", str(tmp_path / "again"))
    assert_one_line_error(code, err, "comfort.toml")
    assert not (tmp_path / "again").exists()


def test_the_readme_counts_a_withdrawal_without_naming_who(tmp_path, capsys):
    """Of three planned participants two drive and one of them withdraws: the package holds one
    participant and its README says 3 planned, 1 with data, 1 withdrawn, and 1 (never created) did
    not take part."""
    study_dir, package = drive_two(tmp_path, 3)
    code, _, err = run_cli(capsys, "withdraw", str(study_dir), "1", "--reason", "asked by mail")
    assert code == 0, err
    code, _, err = run_cli(capsys, "export", str(study_dir), "--out", str(package))
    assert code == 0, err
    readme = (package / "README.md").read_text()
    assert "Participants: 3 planned, 1 with data in this package, 1 withdrawn" in readme
    assert "0 declined consent" in readme and "1 did not take part" in readme
    assert "asked by mail" not in readme and "p00001" not in readme
    episodes = pq.read_table(package / "tables" / "episodes.parquet")
    assert len(set(episodes.column("participant").to_pylist())) == 1


def test_a_withdrawal_names_every_package_that_holds_them_with_their_code_in_each(tmp_path, capsys):
    """A lab shares one package on OSF and another, of another --seed, with a journal: a withdrawal
    afterwards names both packages, each with the participant's code in it, in its line and in the
    audit entry, so that neither keeps the withdrawn person's data unnoticed."""
    study_dir, _ = drive_two(tmp_path, 2)
    packages = [tmp_path / "osf", tmp_path / "journal"]
    for package, seed in zip(packages, ("5", "6"), strict=True):
        code, _, err = run_cli(capsys, "export", str(study_dir), "--out", str(package), "--seed", seed)
        assert code == 0, err
    held = [(str(package.resolve()), package_key(study_dir, package)[1]) for package in packages]
    for package, (_, their_code) in zip(packages, held, strict=True):   # the code is theirs there
        episodes = pq.read_table(package / "tables" / "episodes.parquet").to_pylist()
        assert {row["episode_id"][:7] for row in episodes if row["participant"] == their_code} == {
            f"p{their_code:05d}-"}
    code, out, err = run_cli(capsys, "withdraw", str(study_dir), "1")
    assert code == 0, err
    assert "the 2 packages exported before still hold their data (" in out
    written = {entry["package"]: entry["written_utc"] for entry in read_export_keys(study_dir)}
    for path, their_code in held:
        assert f"{path} (written {written[path]}) as participant {their_code}" in out
    entry = json.loads((study_dir / "live" / "withdrawals.jsonl").read_text())
    assert [(exported["package"], exported["participant"]) for exported in entry["exported"]] == held


def test_the_readme_counts_those_who_declined_without_naming_who(tmp_path, capsys):
    """Of four planned participants two drive, a third declines the consent and a fourth declines
    and is asked again, and does not open the new link: the README counts one who declined and one
    who did not take part (the one asked again), so the counts add up to the four planned, and
    names no one."""
    from trustroute.harness.live.protocol import Consent

    study_dir, package = drive_two(tmp_path, 4)
    study = LiveStudy(tiny_config(tmp_path, participants=4), study_dir, ServerOptions()).open()
    try:
        for label in ("Ada L.", "Grace H."):
            participant = study.create_participant(label)[0]
            study.sessions[participant].handle(Consent(type="consent", agree=False))
        study.ask_again(participant)
        study.replace_token(participant, "new link issued by the experimenter")
    finally:
        study.close()
    code, _, err = run_cli(capsys, "export", str(study_dir), "--out", str(package))
    assert code == 0, err
    readme = (package / "README.md").read_text()
    assert ("Participants: 4 planned, 2 with data in this package, 0 withdrawn (their data deleted "
            "before this export), 1 declined consent (nothing of theirs was recorded), 1 did not take "
            "part (their link not opened, or nothing of theirs recorded after it).") in readme
    assert not re.search(r"Ada|Grace|p0000[23]", readme)


def test_a_live_package_holds_the_task_and_no_token_label_or_path(tmp_path, capsys):
    """A live study's package holds its spec, town, driver model and config file where its
    study_config.json names them, and no byte of any file is a participant's token, its digest or
    label, or a path of the lab's disk."""
    from trustroute.harness.live.auth import token_digest

    config = tiny_config(tmp_path)
    study_dir, package = tmp_path / "study", tmp_path / "package"
    study = LiveStudy(config, study_dir, ServerOptions(pace=1000.0)).open()
    tokens, labels = [], ["Dana Smith", "Room B-12 Tuesday"]
    try:
        with serving(study) as (host, port):
            for p, label in enumerate(labels):
                tokens.append(study.create_participant(label)[1])
                run_scripted(f"ws://{host}:{port}/ws", tokens[-1], ScriptedParticipant(config, p), 120)
    finally:
        study.close()
    code, _, err = run_cli(capsys, "export", str(study_dir), "--out", str(package))
    assert code == 0, err
    assert_task_inputs(package)
    assert_nothing_identifying(package, [*tokens, *map(token_digest, tokens), *labels, str(tmp_path)])
