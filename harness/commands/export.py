"""`trustroute export STUDY --out DIR`: a study packaged for sharing, with pseudonymous
participants, a codebook, the config and the inputs that define the task, the texts shown, the
versions, checksums and a README
(harness/study/export.py; docs/live_studies.md, "Export").

The study directory's lock is held throughout, so a study run or a live server writing the study
refuses the export (one line naming it), as it refuses a second run."""

from __future__ import annotations

from pathlib import Path

import click

from trustroute.core import ranges
from trustroute.core.wording import counted
from trustroute.harness.commands.options import Checked
from trustroute.harness.commands.output import emit, json_option, study_warnings, with_paths


@click.command("export")
@click.argument("study_dir", metavar="STUDY", type=click.Path())
@click.option("--out", "out", type=click.Path(), required=True, help="The package DIRECTORY (new or empty).")
@click.option("--seed", type=Checked(ranges.DRAW_SEED), default=0, show_default=True,
              help="Seed of the pseudonyms' draw (each package's key is kept in STUDY/export-key.json).")
@json_option
def export(study_dir: str, out: str, seed: int, as_json: bool) -> None:
    """Package the consolidated study STUDY for sharing (OSF, a journal) in the --out DIRECTORY."""
    import numpy as np

    from trustroute.analysis.study_directory import load_study
    from trustroute.core.dataset import check_study_dir
    from trustroute.harness.live.withdraw import ended_counts, registry_records, registry_words
    from trustroute.harness.study.export import KEY_FILE, export_study
    from trustroute.harness.study.runner import held_study

    check_study_dir(Path(study_dir))
    # a run writing the study (`study`, `live`) holds its lock: the package is of one state of it,
    # and the key file is written by one command at a time
    with held_study(Path(study_dir), "wait for that run to finish (or stop it), then export again"):
        warnings = study_warnings(Path(study_dir))
        load_study(Path(study_dir))   # its tables checked against its inputs before anything is written
        records = registry_records(Path(study_dir))   # read once for its counts and its words
        index = {**export_study(Path(study_dir), Path(out), np.random.default_rng(seed),
                                ended_counts(records), registry_words(records)),
                 "warnings": warnings}
    # the package is a folder of many files, listed as the folder; the key stays in the study
    paths = {"package": Path(out), "export_key": Path(study_dir) / KEY_FILE}
    line = (f"exported {', '.join(index['tables'])} of {counted(index['participants'], 'participant')} "
            f"to {out} ({index['files']} files, with codebook.md and SHA256SUMS)")
    emit(as_json, with_paths(index, paths), [line])
