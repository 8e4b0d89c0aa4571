"""The study report: report.md and one self-contained report.html (plots inlined as base64 PNG).

Both hold the same content: what was run (config, engine, seeds, hashes, versions), the main
table on the filter beliefs and on beliefs induced from reported trust (each table says which),
the paired tests, the simulated rate beside the exact value and the synthesized [lower, upper],
the paper's figures beside ours, the plots, failures, and notes on reading the numbers.
"""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass
from pathlib import Path

from trustroute.analysis.dataset import REPORT_HTML_FILE, REPORT_MARKDOWN_FILE, read_roads
from trustroute.analysis.plots import write_plots
from trustroute.analysis.tables import StudyAnalysis, cell_rows, study_analysis, study_inputs

NOTES = [
    "Satisfaction is re-evaluated from the logged roads with the spec's DFA (policies.trace). "
    "Belief source 'filter' = the AV's online Bayes filter (belief_after); 'reported' = a point mass on "
    "the driver's last reported trust, carried forward, the AV's initial belief before the first report.",
    "mean trust = mean over episodes of the episode's mean reported trust (as the paper's participants "
    "reported); mean true trust = the synthetic driver's hidden trust averaged over positions.",
    "exact [L, U] = policies.evaluate of the same policy with the study's fallback rule, for the nominal "
    "driver model: with a [population] the simulated drivers differ from it, so the rates may differ.",
    "synthesized [L, U] = the bounds synthesis certified for the policy's own objective (for 'aware': "
    "the probability of acceptance within its synthesis horizon H, 20 by default, not the unbounded "
    "Pr_max of the paper); the study measures the policy followed by the 20-junction fallback, whose "
    "exact value is the 'exact [L, U]' column.",
    "The paper's lowtrust clause `(!lowtrust) U ...` constrains nothing as written (1 - b(1) < 0 is "
    "never true on the simplex, and a U (F b) = F b): see docs/model.md, 'scLDTL'; the strict spec "
    "variants differ.",
    "The paper ran 21 people in CARLA; ours are synthetic drivers from the driver model, so agreement "
    "in direction, not in the third decimal, is what to look for.",
]


@dataclass(frozen=True)
class ReportPaths:
    markdown: Path
    html: Path
    plots: dict
    table_text: str


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(x) for x in row) + " |" for row in rows]
    return "\n".join(lines)


def _html_table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _sections(primary: StudyAnalysis, secondary: StudyAnalysis) -> list[tuple[str, object]]:
    """(title, content) with content a paragraph string, a (header, rows) table, or ("img", key)."""
    manifest = primary.manifest
    config = manifest.get("config", {})
    sections: list[tuple[str, object]] = []
    n_specs, n_conditions = len(config.get("specs", [])), len(config.get("conditions", []))
    failed = len(manifest.get("failed_episodes", []))
    packages = ", ".join(f"{k} {v}" for k, v in manifest.get("packages", {}).items())
    sections.append(
        (
            "Study",
            [
                f"{manifest.get('study')}: {config.get('participants')} participants x {n_specs} specs x "
                f"{n_conditions} conditions, {manifest.get('engine')} engine, seed {config.get('seed')}, "
                "counterbalanced by a Williams Latin square.",
                f"Episodes: {manifest.get('finished_episodes')} finished of "
                f"{manifest.get('planned_episodes')} planned; {failed} failed.",
                f"Config {manifest.get('config_path')} (hash {str(manifest.get('config_hash'))[:16]}), git "
                f"{manifest.get('git_revision')}, created {manifest.get('created_utc')}.",
                f"Packages: {packages}",
            ],
        )
    )
    for analysis in (primary, secondary):
        header, rows = cell_rows(analysis)
        sections.append(
            (
                f"Satisfaction and trust per spec and condition (beliefs: {analysis.belief_source})",
                (header, rows),
            )
        )
    for analysis in (primary, secondary):
        if analysis.paired:
            sections.append(
                (
                    f"Paired tests over participants (beliefs: {analysis.belief_source})",
                    (
                        [
                            "spec",
                            "pair",
                            "pairs",
                            "only A satisfied",
                            "only B satisfied",
                            "McNemar exact p",
                            "Wilcoxon p (reported trust)",
                            "median trust difference",
                        ],
                        [
                            [
                                p["spec"],
                                f"{p['condition_a']} vs {p['condition_b']}",
                                p["pairs"],
                                p["only_a_satisfied"],
                                p["only_b_satisfied"],
                                f"{p['mcnemar_p']:.4f}",
                                f"{p['wilcoxon_p']:.4f}",
                                "-"
                                if p["median_trust_difference"] is None
                                else f"{p['median_trust_difference']:.3f}",
                            ]
                            for p in analysis.paired
                        ],
                    ),
                )
            )
    for analysis in (primary, secondary):
        sections.append(
            (
                f"The paper beside this study (beliefs: {analysis.belief_source})",
                (["figure", "paper", "ours"], [[r["figure"], r["paper"], r["ours"]] for r in analysis.paper]),
            )
        )
    sections.append(("Satisfaction with CIs", ("img", "satisfaction")))
    sections.append(("Trust trajectories", ("img", "trust")))
    sections.append(("Routes driven", ("img", "routes")))
    failures = manifest.get("failed_episodes", [])
    if failures:
        sections.append(
            (
                "Failed episodes",
                (
                    ["episode", "attempts", "error"],
                    [[f["episode_id"], f.get("attempts"), f.get("error")] for f in failures],
                ),
            )
        )
    sections.append(("Notes", NOTES))
    return sections


def write_report(study_dir: Path, analysis: StudyAnalysis | None = None) -> ReportPaths:
    """Analyse (unless given) and write report.md, report.html and plots/ in the study directory."""
    study_dir = Path(study_dir)
    primary = analysis if analysis is not None else study_analysis(study_dir, "filter")
    secondary = study_analysis(study_dir, "reported" if primary.belief_source == "filter" else "filter")
    town, _, _ = study_inputs(primary.manifest)
    roads = read_roads(study_dir, ["episode_id", "index", "directed_road", "trust_after", "reported_trust"])
    plots = write_plots(study_dir, town, primary.cells, roads, primary.episodes, primary.belief_source)
    sections = _sections(primary, secondary)
    title = f"trustroute study report: {primary.manifest.get('study')}"

    md = [f"# {title}", ""]
    body = [f"<h1>{html.escape(title)}</h1>"]
    for heading, content in sections:
        md += [f"## {heading}", ""]
        body.append(f"<h2>{html.escape(heading)}</h2>")
        if isinstance(content, list):
            md += [f"- {line}" for line in content] + [""]
            body.append("<ul>" + "".join(f"<li>{html.escape(line)}</li>" for line in content) + "</ul>")
        elif content[0] == "img":
            png = plots[content[1]]
            md += [f"![{heading}](plots/{png.name})", ""]
            encoded = base64.b64encode(png.read_bytes()).decode()
            body.append(f'<img alt="{html.escape(heading)}" src="data:image/png;base64,{encoded}">')
        else:
            md += [_md_table(*content), ""]
            body.append(_html_table(*content))
    style = (
        "body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em}"
        "table{border-collapse:collapse;margin:1em 0;font-size:0.85em}"
        "td,th{border:1px solid #ccc;padding:3px 6px;text-align:left}th{background:#f3f3f3}"
        "img{max-width:100%}"
    )
    page = (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{style}</style></head><body>{''.join(body)}</body></html>"
    )
    markdown_path, html_path = study_dir / REPORT_MARKDOWN_FILE, study_dir / REPORT_HTML_FILE
    markdown_path.write_text("\n".join(md))
    html_path.write_text(page)
    from trustroute.analysis.tables import format_table

    return ReportPaths(markdown=markdown_path, html=html_path, plots=plots, table_text=format_table(primary))
