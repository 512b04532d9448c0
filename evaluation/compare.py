"""Several Table I reports side by side, against the paper (``crossway evaluate compare``).

Each report is an output folder (or JSON) of ``crossway evaluate table1`` or ``evaluate merge``,
of any scenario and any crossway version: the per-sign table is recomputed from the report's
per-test counts (``evaluation.table1.summarise``), so a report written before the standard error
was recorded gets one too. Writes ``compare.md`` (one row per policy: reach per sign with its
standard error, the paper's figure and how far under it we are, in points), ``compare.csv``
(one row per policy and sign, every outcome) and ``compare.png`` (one panel per junction: each
policy's reach per sign as a dot with +-1 standard error, the paper's figure as a black bar).
"""

from __future__ import annotations

import csv
from pathlib import Path

from evaluation.shares import read_report, report_kind
from evaluation.table1 import OUTCOMES, PAPER_TABLE1, SIGNS, summarise

SCENARIO_ORDER = ("easy", "medium", "hard")  # the paper's order; other scenarios follow, as given
CSV_COLUMNS = ("policy", "scenario", "sign", "goal", "goal_stderr", "crash", "off_path", "time_over", "speed_mps",
               "episodes", "tests", "episodes_per_test", "paper_goal", "short_by_points", "report")


def parse_run(text: str) -> tuple[str | None, Path]:
    """``NAME=PATH`` -> (NAME, PATH); a bare PATH -> (None, PATH): named after its checkpoint."""
    name, equals, path = text.partition("=")
    if equals and name and not Path(text).exists():
        return name, Path(path)
    return None, Path(text)


def load_entry(name: str | None, path: Path) -> dict:
    """One policy's row: its name, scenario, per-sign table and protocol size, from a Table I
    report; refuses another protocol's report, or one without per-test counts, naming the file."""
    kind, report_path = report_kind(path)
    if kind != "table1":
        raise ValueError(f"{path}: a {kind} report; compare takes Table I reports (table1-*.json)")
    report = read_report(report_path)
    try:
        meta, tests = report["meta"], report["tests"]
        scenario = meta["scenario"]
        table = summarise(tests)
    except (KeyError, TypeError) as error:
        raise ValueError(f"{report_path}: not a whole Table I report (no {error})") from None
    if not table:
        raise ValueError(f"{report_path}: the report holds no finished episode")
    checkpoint = meta.get("checkpoint") or "scripted driver"
    partial = meta.get("share") is not None or meta.get("jobs_not_joined", 0) > 0
    return {"name": name or Path(checkpoint).stem, "scenario": scenario, "table": table, "report": str(report_path),
            "tests": len(tests), "episodes_per_test": meta.get("episodes_per_test"), "partial": partial}


def load_entries(runs: list[str]) -> list[dict]:
    """Every run given, parsed and checked before anything is written."""
    if not runs:
        raise ValueError("compare needs at least one Table I report")
    entries = [load_entry(*parse_run(text)) for text in runs]
    seen: dict[tuple[str, str], str] = {}
    for entry in entries:
        key = (entry["name"], entry["scenario"])
        if key in seen:
            raise ValueError(f"two reports are named {entry['name']!r} on {entry['scenario']} ({seen[key]} and "
                             f"{entry['report']}); name them with NAME=PATH")
        seen[key] = entry["report"]
    return entries


def scenarios_of(entries: list[dict]) -> list[str]:
    found = list(dict.fromkeys(entry["scenario"] for entry in entries))
    return [s for s in SCENARIO_ORDER if s in found] + [s for s in found if s not in SCENARIO_ORDER]


def short_by_points(paper: float | None, ours: float) -> float | None:
    """The paper's reach minus ours, in percentage points (negative: above the paper)."""
    return None if paper is None else 100.0 * (paper - ours)


def protocol_text(entry: dict) -> str:
    text = f"{entry['tests']} x {entry['episodes_per_test']}"
    return text + " (a share)" if entry["partial"] else text


def markdown(entries: list[dict]) -> str:
    lines = ["| policy | junction | tests x episodes | reach, " + " / ".join(SIGNS) + " (standard error) "
             "| the paper | under the paper [points] |", "|---|---|---|---|---|---|"]
    for scenario in scenarios_of(entries):
        paper = PAPER_TABLE1.get(scenario, {})
        for entry in (e for e in entries if e["scenario"] == scenario):
            table = entry["table"]
            ours = " / ".join(f"{table[s]['goal']:.3f} ({table[s]['goal_stderr']:.3f})" if s in table else "-"
                              for s in SIGNS)
            theirs = " / ".join(f"{paper[s][0]:.3f}" if s in paper else "-" for s in SIGNS)
            gaps = [short_by_points(paper[s][0], table[s]["goal"]) if s in paper and s in table else None
                    for s in SIGNS]
            gap_text = " / ".join("-" if g is None else f"{g:.1f}" for g in gaps)
            lines.append(f"| {entry['name']} | {scenario} | {protocol_text(entry)} | {ours} | {theirs} | {gap_text} |")
    return "\n".join(lines) + "\n" + markdown_differences(entries)


def difference(first: dict, other: dict) -> tuple[float, float] | None:
    """``other``'s reach minus ``first``'s, in points, and that difference in standard errors of
    the difference (the two taken as independent samples: for runs of the same episodes, which
    are paired, this overstates the uncertainty); None where a sign is missing or no error."""
    if first is None or other is None:
        return None
    error = (first["goal_stderr"] ** 2 + other["goal_stderr"] ** 2) ** 0.5
    points = 100.0 * (other["goal"] - first["goal"])
    return (points, points / (100.0 * error)) if error > 0 else None


def markdown_differences(entries: list[dict]) -> str:
    """Each policy against the first one given on its junction: reach difference per sign in
    points and in standard errors of the difference ("" where no junction has two policies)."""
    lines = []
    for scenario in scenarios_of(entries):
        on_junction = [e for e in entries if e["scenario"] == scenario]
        base = on_junction[0]
        for entry in on_junction[1:]:
            cells = []
            for sign in SIGNS:
                found = difference(base["table"].get(sign), entry["table"].get(sign))
                cells.append("-" if found is None else f"{found[0]:+.1f} ({found[1]:+.1f})")
            lines.append(f"| {entry['name']} | {base['name']} | {scenario} | " + " | ".join(cells) + " |")
    if not lines:
        return ""
    header = ("\nEach policy against the first given on its junction: reach difference in points (in standard errors "
              "of the difference, the runs taken as independent; |2| or more is unlikely to be chance):\n\n"
              "| policy | against | junction | " + " | ".join(SIGNS) + " |\n|---|---|---|" + "---|" * len(SIGNS))
    return header + "\n" + "\n".join(lines) + "\n"


def csv_rows(entries: list[dict]) -> list[dict]:
    rows = []
    for entry in entries:
        paper = PAPER_TABLE1.get(entry["scenario"], {})
        for sign in SIGNS:
            if sign not in entry["table"]:
                continue
            cells = entry["table"][sign]
            paper_goal = paper[sign][0] if sign in paper else None
            gap = short_by_points(paper_goal, cells["goal"])
            rows.append({"policy": entry["name"], "scenario": entry["scenario"], "sign": sign,
                         **{key: cells[key] for key in (*OUTCOMES, "goal_stderr", "speed_mps", "episodes")},
                         "tests": entry["tests"], "episodes_per_test": entry["episodes_per_test"],
                         "paper_goal": paper_goal, "short_by_points": None if gap is None else round(gap, 3),
                         "report": entry["report"]})
    return rows


def write_comparison(entries: list[dict], out_dir: Path, title: str) -> list[Path]:
    from crossway.plot import plot_dot_panels

    out_dir.mkdir(parents=True, exist_ok=True)
    md_path, csv_path, png_path = (out_dir / f"compare.{suffix}" for suffix in ("md", "csv", "png"))
    md_path.write_text(markdown(entries))
    with open(csv_path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        writer.writerows(csv_rows(entries))
    panels = []
    for scenario in scenarios_of(entries):
        paper = PAPER_TABLE1.get(scenario, {})
        series = [(entry["name"], [entry["table"].get(s, {}).get("goal") for s in SIGNS],
                   [entry["table"].get(s, {}).get("goal_stderr") for s in SIGNS])
                  for entry in entries if entry["scenario"] == scenario]
        panels.append((scenario, series, [paper[s][0] if s in paper else None for s in SIGNS]))
    plot_dot_panels(panels, list(SIGNS), png_path, title, "reach", reference_name="the paper")
    return [md_path, csv_path, png_path]
