"""`trustroute analyze` put together for the API and the CLI: the analysis of a study directory
or of a package `trustroute export` wrote (trustroute/core/package.py), an imported study's own
analysis beside it, and the report, written where it may be: a package is published read-only,
so its report goes only into a folder the caller names (`--out`, `out=`), never into the package.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from trustroute.analysis.carla_study.analysis import (
    RealStudyAnalysis,
    real_study_analysis,
    write_real_study_report,
)
from trustroute.analysis.study.analysis import StudyAnalysis, study_analysis
from trustroute.analysis.study.report import ReportPaths, write_report
from trustroute.analysis.study_directory import load_study
from trustroute.core.dataset import CARLA_LOGS_ENGINE
from trustroute.core.output_files import check_output_dir
from trustroute.core.package import check_outside_package, is_package

# why a package of an imported study gives no real-study analysis (the one figure it cannot give)
PACKAGE_REAL_STUDY = ("not available from a package: the real-study analysis reads the CARLA logs' ticks "
                      "(ticks.parquet), which a package does not hold; analyse the study directory")


@dataclass
class AnalyzedStudy:
    """The analysis, an imported study's real-study analysis (None: not one, or `real_note` says
    why not), and the files written, by name (the report's, the real study's)."""

    analysis: StudyAnalysis
    real: RealStudyAnalysis | None = None
    real_note: str = ""
    report: ReportPaths | None = None
    written: dict[str, Path] = field(default_factory=dict)


def report_wanted(study_dir: Path, report: bool | None, default: bool, out: Path | None) -> bool:
    """Whether to write the report, decided once for the CLI and the API, before any work: as asked
    (`report`), else when a folder is named (`out`), else `default` for a study directory and never
    for a package. `out` is the report's folder and nothing else: it is checked (a writable
    directory outside any package, `check_output_dir`) only when the report goes there, and with
    `report` False nothing is written, so it is neither used nor checked. A report asked for a
    package without `out` is an InputError (a package is read-only)."""
    if report is None:
        report = out is not None or (default and not is_package(study_dir))
    if report and out is not None:
        check_output_dir(out, "--out", "report folder")
    elif report:   # into the study directory itself: never a package's
        check_outside_package(Path(study_dir), "--out", "report folder")
    return report


def analyze_study(study_dir: Path, belief_source: str | None, report: bool,
                  out: Path | None = None) -> AnalyzedStudy:
    """The analysis of `study_dir` (a study directory or a package) on `belief_source`, and with
    `report` the report written into `out` (default: the study directory; `report_wanted`)."""

    study_dir = Path(study_dir)
    loaded = load_study(study_dir, package=True)   # read and checked once for all that follows
    result = AnalyzedStudy(study_analysis(study_dir, belief_source=belief_source, loaded=loaded))
    if result.analysis.manifest.get("engine") == CARLA_LOGS_ENGINE:
        if is_package(study_dir):
            result.real_note = PACKAGE_REAL_STUDY
        else:
            result.real = real_study_analysis(study_dir, loaded)
    if report:
        folder = study_dir if out is None else Path(out)
        result.report = write_report(study_dir, analysis=result.analysis, out=folder, loaded=loaded)
        if result.real is not None:
            written = write_real_study_report(result.real, folder)
            result.written = {"real_study_json": written, "real_study_text": written.with_suffix(".txt")}
    return result
