"""The study report: report.md and one self-contained report.html (plots inlined as base64 PNG).

Both are rendered by Jinja2 from the same data (templates/report.md.j2, templates/report.html.j2):
what was run (config, engine, seeds, hashes, versions), the terminal's display tables
(display.py `display_tables`: every table the analysis has rows for) on the leading belief source
and a second one, the takeover, manual-driving, order and carry-over tables, a live study's
questionnaire scores and their paired tests, the sensitivity table, the paper's figures beside
ours when the study is comparable (else a note saying why not), the plots, failures, and notes on
reading the numbers.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from trustroute.analysis.belief_sources import declared_belief_source, default_belief_source, source_label
from trustroute.analysis.formatting import markdown_table
from trustroute.analysis.statistics import BOOTSTRAP_DEGENERATE, BOOTSTRAP_PERCENTILE, WILCOXON_EXACT_PAIRS
from trustroute.analysis.study.analysis import MULTIPLICITY, StudyAnalysis, study_analysis
from trustroute.analysis.study.design import design_text, participants_text
from trustroute.analysis.study.display import (
    APPROXIMATE_MARK,
    display_tables,
    fallback_only_lines,
    format_table,
    order_test_line,
    table_title,
)
from trustroute.analysis.study.plots import write_plots
from trustroute.analysis.study_directory import LoadedStudy, load_study, study_inputs
from trustroute.core.dataset import REPORT_HTML_FILE, REPORT_MARKDOWN_FILE
from trustroute.core.wording import counted

NOTES = [
    "Satisfaction is re-evaluated from the logged roads with the spec's DFA (policies.trace). "
    "Belief source 'filter' = each AV's online Bayes filter (belief_after); 'reported' = a point mass on "
    "the driver's last reported trust, carried forward, the AV's initial belief before the first report; "
    "'reference' = one exact Bayes filter for every condition (the study's driver model, or the "
    "type-aware filter of its population) run on the logged observations; 'true' = the exact filter of "
    "each simulated driver's own model. The primary source is the one the study config declares "
    "(belief_source), else the neutral one: 'true' for simulated studies, 'reported' for live and "
    "imported ones; the sensitivity table shows every comparison on every source.",
    "Every pair of conditions is tested; p-values are shown with their Holm-adjusted values beside "
    "them (the family: one test on one spec over every pair of conditions).",
    "Intervals for rates are exact (Clopper-Pearson) with Wilson beside them, from scipy.stats.binomtest. "
    "Risk differences of paired outcomes use Newcombe's interval for paired proportions; the conditional "
    "odds ratio is b/c of the discordant pairs with the exact interval of b/(b+c); trust differences use a "
    "BCa bootstrap over participants (scipy.stats.bootstrap, 10,000 resamples), as does the 'all specs' "
    "satisfaction difference: a bootstrap bound moves between seeds by a standard deviation of up to "
    "about 0.02 (measured on 14 to 21 participants), so its third decimal is not reliable. Where BCa is "
    "undefined (differences equal up to rounding) the interval is the percentile bootstrap's, marked "
    f"'({BOOTSTRAP_PERCENTILE})'; where every difference is the same there is nothing to resample and the "
    f"interval is the point, marked '({BOOTSTRAP_DEGENERATE})'. Wilcoxon "
    "p-values are exact (the signed-rank sum over every sign flip, ties and zero differences included) up "
    f"to {WILCOXON_EXACT_PAIRS} nonzero differences, beyond that the normal approximation, marked "
    f"'{APPROXIMATE_MARK.strip()}'. The mixed model is fitted by REML, its interval and p-value are Wald's "
    "(normal); a participants' variance estimated at 0 is said in its note. p-values are printed in "
    "scientific notation.",
    "The 'all specs' row is per participant (the mean over specs of each participant's difference); its "
    "satisfaction test is the exact two-sided sign test of the participants ahead under A against those "
    "ahead under B (participants without a difference dropped), and the repeated-measures models use "
    "one group per participant, so a participant's episodes under several specs never count as independent "
    "pairs. Separation is checked from the data before the "
    "conditional logit is fitted; on separated data the row shows the exact conditional odds ratio of "
    "the matched pairs and says why in its note.",
    "mean trust = mean over episodes of the episode's mean reported trust (as the paper's participants "
    "reported); mean true trust = the synthetic driver's hidden trust averaged over positions (in a "
    "study of people, mean stated trust: the participant's latest report, or their trust at the start).",
    "exact [L, U] = the exact evaluation (policies/evaluation) of the same policy with the study's "
    "fallback rule, for the nominal driver model: with a [population] the simulated drivers differ "
    "from it, so the rates may differ.",
    "synthesized [L, U] = the bounds synthesis certified for the policy's own objective (for 'aware': "
    "the probability of acceptance within its synthesis horizon H, 20 by default, not the unbounded "
    "Pr_max of the paper); the study measures the policy followed by the 20-junction fallback, whose "
    "exact value is the 'exact [L, U]' column.",
    "The paper's lowtrust clause `(!lowtrust) U ...` constrains nothing as written (1 - b(1) < 0 is "
    "never true on the simplex, and a U (F b) = F b): see docs/model.md, 'scLDTL'; the strict spec "
    "variants differ.",
    "Per true driver type (studies with a [drivers] population): each participant's type is drawn "
    "from the population's weights and logged; the per-type tables split the cells and the paired "
    "statistics (every pair of conditions) by it, 'all' being every participant. A type with few "
    "participants has wide intervals; the exact [L, U] above stays that of the nominal model.",
    "The paper ran 21 people in CARLA; ours are synthetic drivers from the driver model, so agreement "
    "in direction, not in the third decimal, is what to look for.",
]
PLOT_TITLES = {
    "satisfaction": "Satisfaction with exact CIs",
    "participants": "Per participant, paired",
    "trust": "Trust over the episodes",
    "takeovers": "Takeovers per incident type",
    "routes": "Routes driven",
}
# The report's sections of display tables (display.py `display_tables`), each table in one: those
# shown on each belief source of the report, those shown once (on the leading source: the figures of
# most do not depend on it), and the sensitivity and paper tables, which have sections of their own.
PER_SOURCE_TABLES = ("cells", "paired", "repeated", "per_type", "per_type_paired")
ONCE_TABLES = ("takeovers", "manual", "order", "carryover", "questionnaires", "questionnaire_tests")
OWN_SECTION_TABLES = ("sensitivity", "paper")
# The templates ship with the analysis package (pyproject package-data), beside this subpackage.
TEMPLATES = Path(__file__).resolve().parents[1] / "templates"


@dataclass(frozen=True)
class ReportPaths:
    markdown: Path
    html: Path
    plots: dict
    table_text: str


def _environment():
    import jinja2

    environment = jinja2.Environment(
        loader=jinja2.FileSystemLoader(TEMPLATES),
        autoescape=jinja2.select_autoescape(enabled_extensions=("html.j2",), default_for_string=False),
        trim_blocks=True,
        lstrip_blocks=True,
        undefined=jinja2.StrictUndefined,
    )
    environment.filters["markdown"] = markdown_table
    return environment


def study_lines(manifest: dict, episodes: pd.DataFrame) -> list[str]:
    """What was run: the design (participants from the episodes when the config has no count or
    counts those planned, the order as the data show it), the episodes, the config and the
    versions."""
    config = manifest.get("config", {})
    n_specs, n_conditions = len(config.get("specs", [])), len(config.get("conditions", []))
    failed = len(manifest.get("failed_episodes", []))
    packages = ", ".join(f"{k} {v}" for k, v in manifest.get("packages", {}).items())
    return [
        f"{manifest.get('study')}: {participants_text(manifest, episodes)} x {counted(n_specs, 'spec')} "
        f"x {counted(n_conditions, 'condition')}, {manifest.get('engine')} engine, "
        f"{design_text(manifest, episodes)}.",
        f"Episodes: {manifest.get('finished_episodes')} finished of "
        f"{manifest.get('planned_episodes')} planned; {failed} failed.",
        f"{config_text(manifest)}, trustroute's git revision {manifest.get('git_revision')}, "
        f"created {manifest.get('created_utc')}.",
        f"Packages: {packages}",
    ]


def config_text(manifest: dict) -> str:
    """The config a study ran from, or where its episodes came from when no config made them (an
    import of logs records its source instead)."""
    if manifest.get("config_path") is None:
        return f"No config: episodes imported from {manifest.get('source') or 'logs'}"
    return f"Config {manifest['config_path']} (hash {str(manifest.get('config_hash'))[:16]})"


SENSITIVITY_LINE = ("Each comparison's satisfaction difference (A − B, per spec: Newcombe's interval; all "
                    "specs: the participants' mean difference, BCa bootstrap, its method named where it is "
                    "another as in the paired table) on every belief source the "
                    "study has; the tables above lead with the one marked primary. 'filter' scores each "
                    "condition on its own AV's belief and 'reference' on the type-aware filter (the "
                    "robust AV's own), so neither is neutral when the conditions' filters differ.")


def second_source(primary: StudyAnalysis) -> str:
    """The source of the report's second set of tables: the reports, or when they lead, the first
    other source the study has of "true" and "filter"."""
    if primary.belief_source != "reported":
        return "reported"
    columns = primary.episodes.columns
    return next((s for s in ("true", "filter") if f"satisfied_{s}" in columns), "filter")


def sources_line(lead: str, second: str, default: str, declared: bool = False, note: str = "") -> str:
    """The report's statement of which belief source leads its tables (`note`: why the default
    could not lead)."""
    if note:
        chosen = note
    elif lead != default:
        chosen = (f"chosen by the caller (--belief-source, or analyze(belief_source=...)); this study's "
                  f"primary source is {default!r}")
    elif declared:
        chosen = "the primary source the study config declared"
    else:
        chosen = "the neutral default for this study: the same for every condition, no condition's own filter"
    return (f"Leading belief source: {lead!r} ({source_label(lead)}; {chosen}). "
            f"The tables on {second!r} ({source_label(second)}) follow them.")


def _analysis_view(analysis: StudyAnalysis) -> dict:
    return {
        "belief_source": analysis.belief_source,
        "tables": display_tables(analysis),
        "order_line": order_test_line(analysis.order_tests) if analysis.order_tests else "",
        "paper_note": analysis.paper_note,
    }


def write_report(study_dir: Path, analysis: StudyAnalysis | None = None,
                 out: Path | None = None, loaded: LoadedStudy | None = None) -> ReportPaths:
    """Analyse (unless given) and write report.md, report.html and plots/ in `out` (default: the
    study directory). `loaded`: the study as `analysis` read it (`study_analysis`), so that the
    report's second analysis reads and checks nothing again; read here when not given."""
    study_dir = Path(study_dir)
    folder = study_dir if out is None else Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    loaded = load_study(study_dir, package=True) if loaded is None else loaded
    primary = analysis if analysis is not None else study_analysis(study_dir, loaded=loaded)
    default = default_belief_source(primary.manifest)
    secondary = study_analysis(study_dir, second_source(primary), loaded=loaded)
    town, _, specs = study_inputs(primary.manifest, study_dir)
    roads = loaded[2][["episode_id", "index", "directed_road", "trust_after", "reported_trust"]]
    plots = write_plots(folder, town, primary, roads, specs)
    failures = primary.manifest.get("failed_episodes", [])
    context = {
        "title": f"trustroute study report: {primary.manifest.get('study')}",
        "study_lines": study_lines(primary.manifest, primary.episodes),
        "warnings": fallback_only_lines(primary.manifest),
        "sources_line": sources_line(primary.belief_source, secondary.belief_source, default,
                                     declared_belief_source(primary.manifest) is not None,
                                     primary.source_note),
        "multiplicity": MULTIPLICITY,
        "sensitivity_line": SENSITIVITY_LINE,
        "analyses": [_analysis_view(primary), _analysis_view(secondary)],
        "title_of": table_title,
        "per_source_tables": PER_SOURCE_TABLES,
        "once_tables": ONCE_TABLES,
        "plots": [
            {
                "title": PLOT_TITLES[name],
                "file": plots[name].name,
                "base64": base64.b64encode(plots[name].read_bytes()).decode(),
            }
            for name in PLOT_TITLES
            if name in plots
        ],
        "failures": pd.DataFrame(failures, columns=["episode_id", "attempts", "error"]) if failures else None,
        "notes": NOTES,
    }
    environment = _environment()
    markdown_path, html_path = folder / REPORT_MARKDOWN_FILE, folder / REPORT_HTML_FILE
    markdown_path.write_text(environment.get_template("report.md.j2").render(**context))
    html_path.write_text(environment.get_template("report.html.j2").render(**context))
    return ReportPaths(markdown=markdown_path, html=html_path, plots=plots, table_text=format_table(primary))
