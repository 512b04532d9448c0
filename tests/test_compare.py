"""``crossway evaluate compare``: Table I reports side by side, on the project's own committed
reports (real runs), read back as CSV, Markdown and PNG pixels."""

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from crossway.plot import COLOURS
from evaluation.compare import CSV_COLUMNS, load_entry, parse_run, protocol_text
from test_plot import pixels

RESULTS = Path(__file__).resolve().parent.parent / "docs" / "results"
EASY = RESULTS / "pretrain-easy-guard" / "table1-easy-full"  # written with goal_stderr
HARD_RULE = RESULTS / "hard-ensemble9-braking" / "table1-hard-full"
HARD_NINE = RESULTS / "median-students-ens9" / "table1-hard-full-ens9ab"
OLD_EASY = RESULTS / "easy-table1" / "table1-easy.json"  # session 3's format: no goal_stderr, no jobs
ROW_MEDIUM = RESULTS / "row-medium-priority"


def crossway(*args):
    return subprocess.run([sys.executable, "-m", "crossway", *args], capture_output=True, text=True, timeout=120)


def columns_of(image: np.ndarray, colour) -> np.ndarray:
    target = np.round(np.array(colour) * 255).astype(int)
    return np.flatnonzero(np.all(np.abs(image.astype(int) - target) <= 2, axis=2).any(axis=0))


def test_compare_puts_reports_side_by_side_with_the_paper(tmp_path):
    out = tmp_path / "cmp"
    result = crossway("evaluate", "compare", f"guard={EASY}", f"nine+rule={HARD_RULE}", f"nine={HARD_NINE}",
                      "--out", str(out))
    assert result.returncode == 0, result.stderr
    rows = list(csv.DictReader(open(out / "compare.csv")))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert [(r["policy"], r["scenario"]) for r in rows[::3]] == [("guard", "easy"), ("nine+rule", "hard"),
                                                                 ("nine", "hard")]
    for directory, name, scenario in ((EASY, "guard", "easy"), (HARD_RULE, "nine+rule", "hard")):
        report = json.loads(next(directory.glob("table1-*.json")).read_text())
        for row in (r for r in rows if r["policy"] == name):
            recorded = report["table"][row["sign"]]
            # recomputed from the per-test counts, the table is the one the run wrote
            assert math.isclose(float(row["goal"]), recorded["goal"], rel_tol=1e-12)
            assert math.isclose(float(row["goal_stderr"]), recorded["goal_stderr"], rel_tol=1e-12)
            assert int(row["episodes"]) == recorded["episodes"] and row["scenario"] == scenario
            paper = report["paper"][row["sign"]][0]
            assert math.isclose(float(row["short_by_points"]), 100 * (paper - recorded["goal"]), abs_tol=1e-3)
    stop = next(r for r in rows if r["policy"] == "nine+rule" and r["sign"] == "stop")
    assert float(stop["short_by_points"]) < 0  # above the paper's 0.972 at stop signs (0.973)
    page = (out / "compare.md").read_text()
    assert "| guard | easy | 3 x 3000 | 0.981 (0.002) / 0.984 (0.002) / 0.984 (0.002) | 0.998 / 0.995 / 0.992 |" in page
    assert "| nine | hard | 10 x 3000 | 0.973 (0.002) / 0.975 (0.002) / 0.968 (0.002) |" in page
    assert page == result.stdout.rsplit("wrote ", 1)[0]  # the page is what the command printed
    # the nine against the nine with the rule (the first on hard), by hand from the two reports
    rule, nine = (json.loads(next(d.glob("table1-*.json")).read_text())["table"] for d in (HARD_RULE, HARD_NINE))
    cells = []
    for sign in ("none", "yield", "stop"):
        points = 100 * (nine[sign]["goal"] - rule[sign]["goal"])
        error = 100 * math.hypot(nine[sign]["goal_stderr"], rule[sign]["goal_stderr"])
        cells.append(f"{points:+.1f} ({points / error:+.1f})")
    assert "| nine | nine+rule | hard | " + " | ".join(cells) + " |" in page
    assert cells[2] == "-0.5 (-2.2)"  # the rule's gain at stop signs: 0.5 points, 2.2 standard errors
    assert "| guard |" not in page.split("Each policy against")[1]  # alone on its junction: no row
    image = pixels(out / "compare.png")
    panel, gap, left = 260, 16, 70
    assert image.shape[1] == left + 20 + 2 * panel + gap  # two junctions, two panels
    # each policy's dots lie in its own junction's panel, and nowhere else
    easy_panel, hard_panel = (left, left + panel), (left + panel + gap, left + 2 * panel + gap)
    plot_rows = image[:-(40 + 18 * 4)]  # above the legend
    for colour, (low, high) in ((COLOURS[0], easy_panel), (COLOURS[1], hard_panel), (COLOURS[2], hard_panel)):
        columns = columns_of(plot_rows, colour)
        assert len(columns) and columns.min() > low and columns.max() < high


def test_an_old_report_gets_its_standard_error_from_its_counts():
    report = json.loads(OLD_EASY.read_text())
    assert "goal_stderr" not in report["table"]["stop"]
    entry = load_entry(None, OLD_EASY)
    assert entry["name"] == "easy" and entry["scenario"] == "easy" and entry["tests"] == 3
    by_test = [t["counts"]["stop"] for t in report["tests"]]
    fractions = [(c.get("goal", 0) / sum(c.values()), sum(c.values())) for c in by_test]
    by_hand = math.sqrt(sum(p * (1 - p) / n for p, n in fractions)) / len(fractions)
    assert math.isclose(entry["table"]["stop"]["goal_stderr"], by_hand, rel_tol=1e-12)
    assert math.isclose(entry["table"]["stop"]["goal"], report["table"]["stop"]["goal"], rel_tol=1e-12)


def test_names_come_from_name_equals_or_the_checkpoint(tmp_path):
    assert parse_run(f"a=b={EASY}") == ("a", Path(f"b={EASY}"))
    assert parse_run(str(EASY)) == (None, EASY)
    odd = tmp_path / "x=y"  # a folder whose own name holds '=' is a path, not NAME=PATH
    odd.mkdir()
    assert parse_run(str(odd)) == (None, odd)
    assert load_entry(None, HARD_RULE)["name"] == "hard-ensemble9-braking"
    # a share of a protocol says so; a run of fewer episodes per test is a whole, smaller protocol
    assert protocol_text(load_entry(None, RESULTS / "median-students-ens9" / "table1-hard-share2-ens9ab")) == \
        "10 x 1500 (a share)"
    assert protocol_text(load_entry(None, RESULTS / "median-students-ens9" / "table1-hard-half-ens9ab")) == "10 x 1500"


def test_compare_refuses_bad_input_and_writes_nothing(tmp_path):
    out = tmp_path / "cmp"
    cases = [
        ((str(EASY), str(ROW_MEDIUM)), "a right-of-way report; compare takes Table I reports"),
        ((f"same={HARD_RULE}", f"same={HARD_NINE}"), "two reports are named 'same' on hard"),
        ((str(tmp_path / "missing"),), "no such file or folder"),
        ((str(RESULTS),), "expected one report"),
    ]
    for runs, message in cases:
        result = crossway("evaluate", "compare", *runs, "--out", str(out))
        assert result.returncode == 2, (runs, result.stderr)
        assert message in result.stderr, (runs, result.stderr)
        assert not out.exists()
    broken = tmp_path / "table1-easy.json"
    broken.write_text(json.dumps({"meta": {"scenario": "easy"}, "tests": []}))
    result = crossway("evaluate", "compare", str(broken), "--out", str(out))
    assert result.returncode == 2 and "holds no finished episode" in result.stderr
    assert not out.exists()
