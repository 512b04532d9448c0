"""The paper's Table I protocol (section "Results").

For a scenario trained with delays up to D seconds, run tests with delay_min = 0 and delay_max
= 10, 20, ..., D seconds (3 tests for easy, 5 for medium, 10 for hard); each test counts
``episodes`` finished episodes (episodes cut short by a sign change are not counted, only
reported as ``cut_by_redraw``). Per
traffic sign, report the fractions of reaches, crashes, off-roads and time-overs and the
average speed, each averaged over the tests.
"""

from __future__ import annotations

import json
import math
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from evaluation.parallel import (cache_salt, clear_partial, file_digest, kept_jobs, numeric_platform, partial_dir,
                                 platform_line, run_parallel)
from evaluation.shares import (check_contiguous, check_same_protocol, jobs_text, merged_meta, part_record, share_range,
                               unpack, workers_text)
from simcore.controller import DriverOptions
from simcore.dynamics import DT

if TYPE_CHECKING:
    from simcore.scenario import ScenarioSpec

SIGNS = ("none", "yield", "stop")
OUTCOMES = ("goal", "crash", "off_path", "time_over")
COLUMN_NAMES = {"goal": "Reaches", "crash": "Crashes", "off_path": "Off-roads", "time_over": "Time-overs"}

CHUNK_EPISODES = 500  # a test's episodes per worker job
# how an episode began: at the reset of its chunk's simulator (every lane's first episode of the
# chunk, all lanes at once: SimConfig.start_all_at_reset), within BURST_WINDOW_S after a sign redraw
# of the hard junction (with sign_change_restart "together" every lane starts then, eight cars at
# once), or otherwise
STARTS = ("reset", "burst", "staggered")
BURST_WINDOW_S = 2 * DT  # [s]


def began_in_burst(start_s: float | None, redraws_s: list[float]) -> bool:
    """Whether an episode that began at ``start_s`` (None: before anything was recorded) began in
    the burst after a sign redraw (``redraws_s``: when they were due, oldest first). The last two
    suffice: an episode can end in the very step of a redraw, before the next one."""
    return start_s is not None and any(0.0 < start_s - r <= BURST_WINDOW_S + 1e-9 for r in redraws_s[-2:])

# Table I of the paper: per scenario and sign, (reaches, crashes, off-roads, time-overs, speed m/s)
PAPER_TABLE1 = {
    "easy": {"none": (0.998, 0.002, 0.0, 0.0, 8.533), "yield": (0.995, 0.005, 0.0, 0.0, 8.280),
             "stop": (0.992, 0.008, 0.0, 0.0, 8.105)},
    "medium": {"none": (0.995, 0.005, 0.0, 0.0, 8.394), "yield": (0.991, 0.009, 0.0, 0.0, 7.939),
               "stop": (0.992, 0.008, 0.0, 0.0, 7.446)},
    "hard": {"none": (0.997, 0.003, 0.0, 0.0, 8.244), "yield": (0.991, 0.009, 0.0, 0.0, 7.365),
             "stop": (0.972, 0.012, 0.0, 0.016, 5.855)},
}


@dataclass(frozen=True)
class TestSpec:
    scenario: ScenarioSpec | str  # the spec itself: a scenario file need not exist in the worker
    delay_max_s: float
    episodes: int
    seed: int
    checkpoint: str | None  # None: the scripted driver (a reference, and a stand-in for tests and smoke runs)
    scripted: DriverOptions = DriverOptions()  # the scripted driver's options, without a checkpoint


def delay_schedule(training_delay_max_s: float) -> list[float]:
    """10, 20, ... up to the training delay_max (paper: 3, 5 and 10 tests)."""
    count = max(1, int(round(training_delay_max_s / 10.0)))
    return [10.0 * (i + 1) for i in range(count)]


def chunks_of(test: TestSpec) -> list[TestSpec]:
    """A test as the jobs the protocol runs: chunks of at most CHUNK_EPISODES episodes, each with
    its own simulator and seed (the test's, + 1000 per chunk), so every worker stays busy to the
    end; the chunks do not depend on --workers."""
    return [replace(test, episodes=min(CHUNK_EPISODES, test.episodes - start),
                    seed=test.seed + 1000 * (start // CHUNK_EPISODES))
            for start in range(0, test.episodes, CHUNK_EPISODES)]


def start_test(spec: TestSpec):
    """A job's simulator, just reset (every lane starting), its first ``StepResult`` and the driver's
    ``act(result)`` -> actions [slots, 2]: the set-up ``run_test`` drives, for scripts that replay it."""
    from evaluation.policy import PolicyDriver, load_policy  # looked up at call time (sign_split.py swaps it)
    from simcore.controller import scripted_driver
    from simcore.simulator import SimConfig, Simulator

    sim = Simulator(spec.scenario, SimConfig(delay_min_s=0.0, delay_max_s=spec.delay_max_s,
                                             observe=spec.checkpoint is not None), seed=spec.seed)
    result = sim.reset()
    if spec.checkpoint is not None:
        act = PolicyDriver(sim, load_policy(spec.checkpoint)).act
    else:
        scripted = scripted_driver(sim, spec.scripted)
        act = lambda _result: scripted.act()  # noqa: E731 - it reads the simulator itself
    return sim, result, act


def run_test(spec: TestSpec, progress=None) -> dict:
    """One test: counts per sign and end reason, summed speeds; runs in a worker process."""
    import torch

    torch.set_num_threads(1)
    sim, result, act = start_test(spec)
    counts: dict[str, Counter] = defaultdict(Counter)
    by_start: dict[str, dict[str, Counter]] = {kind: defaultdict(Counter) for kind in STARTS}
    speed_sum: Counter = Counter()
    cut: Counter = Counter()  # sign -> episodes cut short by a sign redraw (not counted)
    # the counted episodes that began at least the time limit before the next redraw: no redraw
    # could have cut them, so their outcomes are not thinned by the cut
    uncuttable: dict[str, Counter] = defaultdict(Counter)
    started_s = {v: sim.time_s for v in np.flatnonzero(result.started).tolist()}  # slot -> its episode's start [s]
    reset_s = sim.time_s  # when the reset started every lane [s]; later episodes begin after it
    redraw_due_s = dict.fromkeys(started_s, sim.next_sign_change_s)  # slot -> the next redraw when it began [s]
    redraws_s: list[float] = []  # when the signs were redrawn and every lane restarted [s]
    driver = getattr(act, "__self__", None)  # a PolicyDriver; the scripted driver's act is a plain function
    braking = getattr(driver, "emergency_braking", None)  # algo.braking: count where it overrode the network
    car_steps = 0
    done = 0
    while done < spec.episodes:
        next_redraw_s = sim.next_sign_change_s
        result = sim.step(act(result))
        car_steps += int(result.acted.sum())
        if sim.next_sign_change_s != next_redraw_s:
            redraws_s.append(next_redraw_s)  # when it was due (also when the road stood empty)
        for episode in result.episodes:
            start_s = started_s.pop(episode.slot, None)
            due_s = redraw_due_s.pop(episode.slot, None)
            if episode.end_reason not in OUTCOMES or done >= spec.episodes:
                if episode.end_reason == "sign_change" and done < spec.episodes:
                    cut[episode.sign] += 1
                continue  # cut short by a sign change: not an outcome
            counts[episode.sign][episode.end_reason] += 1
            speed_sum[episode.sign] += episode.mean_speed_mps
            kind = ("reset" if start_s == reset_s else "burst" if began_in_burst(start_s, redraws_s)
                    else "staggered")
            by_start[kind][episode.sign][episode.end_reason] += 1
            if (sim.sign_interval_s > 0.0 and start_s is not None and due_s is not None
                    and start_s + sim.time_limit_s + DT <= due_s + 1e-9):
                uncuttable[episode.sign][episode.end_reason] += 1
            done += 1
            if progress is not None and done % 25 == 0:
                progress.put(25)
        for slot in np.flatnonzero(result.started).tolist():
            started_s[slot] = sim.time_s
            redraw_due_s[slot] = sim.next_sign_change_s
    if progress is not None and done % 25:
        progress.put(done % 25)
    report = {"delay_max_s": spec.delay_max_s, "counts": {s: dict(c) for s, c in counts.items()},
              "speed_sum": dict(speed_sum), "cut_by_redraw": dict(cut),
              "counts_uncuttable": {s: dict(c) for s, c in uncuttable.items()},
              "counts_by_start": {k: {s: dict(c) for s, c in v.items()} for k, v in by_start.items()}}
    if braking is not None:  # car-steps driven, and those where the emergency braking overrode the network
        report.update(car_steps=car_steps, braked_car_steps=driver.braked_car_steps)
    return report


def add_counts(total: dict[str, dict[str, int]], counts: dict[str, dict[str, int]]) -> None:
    """Adds ``counts`` (sign -> end reason -> episodes) into ``total``, in place."""
    for sign, reasons in counts.items():
        into = total.setdefault(sign, {})
        for reason, count in reasons.items():
            into[reason] = into.get(reason, 0) + count


def merge_chunks(parts: list[dict]) -> list[dict]:
    """Chunks of the same test (same delay_max) summed into one result per test, in order."""
    merged: dict[float, dict] = {}
    for part in parts:
        test = merged.setdefault(part["delay_max_s"], {"delay_max_s": part["delay_max_s"], "counts": {},
                                                       "speed_sum": {}, "cut_by_redraw": {}})
        add_counts(test["counts"], part["counts"])
        for sign, speed in part["speed_sum"].items():
            test["speed_sum"][sign] = test["speed_sum"].get(sign, 0.0) + speed
        for sign, count in part.get("cut_by_redraw", {}).items():  # absent in results kept before session 30
            test["cut_by_redraw"][sign] = test["cut_by_redraw"].get(sign, 0) + count
        add_counts(test.setdefault("counts_uncuttable", {}), part.get("counts_uncuttable", {}))
        for kind, counts in part.get("counts_by_start", {}).items():  # absent in results kept before session 28
            add_counts(test.setdefault("counts_by_start", {}).setdefault(kind, {}), counts)
        for key in ("car_steps", "braked_car_steps"):  # only where a policy drove with emergency braking
            if key in part:
                test[key] = test.get(key, 0) + part[key]
    return list(merged.values())


def by_start(tests: list[dict]) -> dict:
    """Per kind of start (``STARTS``) and sign (and "all"): the episodes of every test pooled, and
    each outcome's fraction of them; {} for tests run without that record."""
    table: dict[str, dict] = {}
    for kind in STARTS:
        rows = pooled_rows([test.get("counts_by_start", {}).get(kind, {}) for test in tests])
        if rows:
            table[kind] = rows
    return table


def pooled_rows(counts: list[dict[str, dict[str, int]]]) -> dict:
    """Per sign (and "all"): the episodes of every ``counts`` (sign -> end reason -> episodes)
    pooled, and each outcome's fraction of them; signs without episodes left out."""
    pooled: dict[str, Counter] = defaultdict(Counter)
    for by_sign in counts:
        for sign, reasons in by_sign.items():
            pooled[sign].update(reasons)
            pooled["all"].update(reasons)
    rows = {}
    for sign in (*SIGNS, "all"):
        total = sum(pooled[sign].values())
        if total:
            rows[sign] = {"episodes": total, **{o: pooled[sign][o] / total for o in OUTCOMES}}
    return rows


def markdown_starts(table: dict) -> str:
    """Reach, crashes and time-overs per kind of start and sign (``by_start``)."""
    groups = (*SIGNS, "all")
    header = ("| began | " + " | ".join(f"{g}: reaches / crashes / time-overs (episodes)" for g in groups) + " |")
    lines = [header, "|---|" + "---|" * len(groups)]
    for kind, rows in table.items():
        cells = [f"{rows[g]['goal']:.3f} / {rows[g]['crash']:.3f} / {rows[g]['time_over']:.3f} ({rows[g]['episodes']})"
                 if g in rows else "-" for g in groups]
        lines.append(f"| {kind} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def summarise(tests: list[dict]) -> dict:
    """Per sign: each outcome's fraction and the mean speed, averaged over the tests, and the
    standard error of the averaged reach (``goal_stderr``: each test a binomial sample,
    sqrt(sum p_i (1 - p_i) / n_i) / k over its k tests)."""
    table = {}
    per_test = per_test_rows(tests)
    for sign in SIGNS:
        rows = [r for r in per_test if r["sign"] == sign]
        if rows:
            table[sign] = {key: sum(r[key] for r in rows) / len(rows) for key in (*OUTCOMES, "speed_mps")}
            variance = sum(r["goal"] * (1.0 - r["goal"]) / r["episodes"] for r in rows)
            table[sign]["goal_stderr"] = variance ** 0.5 / len(rows)
            table[sign]["episodes"] = sum(r["episodes"] for r in rows)
    return table


def per_test_rows(tests: list[dict]) -> list[dict]:
    """One row per test and sign (and "all", the test's episodes of every sign together): its
    episodes, the fraction of each outcome and the mean speed [m/s]; the tests of Table I
    before they are averaged."""
    rows = []
    for test in tests:
        groups = [(sign, test["counts"].get(sign, {}), test["speed_sum"].get(sign, 0.0)) for sign in SIGNS]
        every = Counter()
        for _, counts, _ in groups:
            every.update(counts)
        groups.append(("all", dict(every), sum(test["speed_sum"].get(sign, 0.0) for sign in SIGNS)))
        for sign, counts, speed_sum in groups:
            total = sum(counts.values())
            if total == 0:
                continue
            row = {"delay_max_s": test.get("delay_max_s"), "sign": sign, "episodes": total}
            row.update({o: counts.get(o, 0) / total for o in OUTCOMES})
            row["speed_mps"] = speed_sum / total
            rows.append(row)
    return rows


def markdown(scenario: str, table: dict) -> str:
    paper = PAPER_TABLE1.get(scenario, {})
    header = "| | " + " | ".join(f"{s} (ours) | {s} (paper)" for s in SIGNS) + " |"
    lines = [header, "|---|" + "---|" * (2 * len(SIGNS))]
    for i, outcome in enumerate((*OUTCOMES, "speed_mps")):
        name = COLUMN_NAMES.get(outcome, "Average speed [m/s]")
        cells = []
        for sign in SIGNS:
            ours = table.get(sign, {}).get(outcome)
            theirs = paper.get(sign, (None,) * 5)[i]
            fmt = "{:.3f}"
            cells += [fmt.format(ours) if ours is not None else "-", fmt.format(theirs) if theirs is not None else "-"]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    errors = (f"{table[s]['goal_stderr']:.3f} | -" if s in table else "- | -" for s in SIGNS)
    lines.append("| Reaches, standard error | " + " | ".join(errors) + " |")
    counts = (f"{table.get(s, {}).get('episodes', 0)} | 3000 per test" for s in SIGNS)
    lines.append("| Episodes | " + " | ".join(counts) + " |")
    return "\n".join(lines) + "\n"


def markdown_tests(rows: list[dict]) -> str:
    """The per-test table: reach (and crashes) per sign and over all signs, one line per test."""
    groups = (*SIGNS, "all")
    header = "| delay_max [s] | " + " | ".join(f"{g}: reaches / crashes (episodes)" for g in groups) + " |"
    lines = [header, "|---|" + "---|" * len(groups)]
    by_test: dict[float, dict[str, dict]] = defaultdict(dict)
    for row in rows:
        by_test[row["delay_max_s"]][row["sign"]] = row
    for delay, cells in by_test.items():
        text = [f"{cells[g]['goal']:.3f} / {cells[g]['crash']:.3f} ({cells[g]['episodes']})" if g in cells else "-"
                for g in groups]
        lines.append(f"| {delay:g} | " + " | ".join(text) + " |")
    return "\n".join(lines) + "\n"


def markdown_braking(tests: list[dict]) -> str:
    """How often the policy's emergency braking (``algo.braking``) overrode the network, per test;
    "" for runs without it."""
    braked = [t for t in tests if "braked_car_steps" in t]
    if not braked:
        return ""
    cells = ", ".join(f"{t['braked_car_steps'] / max(t['car_steps'], 1):.2%} at {t['delay_max_s']:g} s" for t in braked)
    steps, total = sum(t["braked_car_steps"] for t in braked), sum(t["car_steps"] for t in braked)
    return (f"\nThe policy's emergency braking (algo/braking.py) overrode the network in {steps} of {total} "
            f"car-steps ({steps / max(total, 1):.2%}): {cells}.\n")


def write_outputs(out_dir: Path, scenario: str, tests: list[dict], table: dict, meta: dict) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = out_dir / f"table1-{scenario}"
    json_path = stem.with_suffix(".json")
    starts = by_start(tests)
    json_path.write_text(json.dumps({"meta": meta, "tests": tests, "table": table, "by_start": starts,
                                     "uncuttable": pooled_rows([t.get("counts_uncuttable", {}) for t in tests]),
                                     "paper": PAPER_TABLE1.get(scenario)}, indent=2))
    csv_path = stem.with_suffix(".csv")
    paper = PAPER_TABLE1.get(scenario, {})
    rows = ["sign,metric,ours,paper"]
    for sign in SIGNS:
        for i, metric in enumerate((*OUTCOMES, "speed_mps", "goal_stderr")):
            ours = table.get(sign, {}).get(metric)
            theirs = paper.get(sign, (None,) * 5)[i] if i < 5 else None  # the paper gives no error
            rows.append(f"{sign},{metric},{'' if ours is None else round(ours, 5)},{'' if theirs is None else theirs}")
    csv_path.write_text("\n".join(rows) + "\n")
    test_rows = per_test_rows(tests)
    tests_csv_path = out_dir / f"table1-{scenario}-tests.csv"
    columns = ("delay_max_s", "sign", "episodes", *OUTCOMES, "speed_mps")
    lines = [",".join(columns)]
    lines += [",".join(str(round(r[c], 5)) if isinstance(r[c], float) else str(r[c]) for c in columns)
              for r in test_rows]
    tests_csv_path.write_text("\n".join(lines) + "\n")
    starts_csv_path = out_dir / f"table1-{scenario}-starts.csv"
    columns = ("began", "sign", "episodes", *OUTCOMES)
    lines = [",".join(columns)]
    lines += [",".join([kind, sign, str(row["episodes"]), *(str(round(row[o], 5)) for o in OUTCOMES)])
              for kind, rows in starts.items() for sign, row in rows.items()]
    starts_csv_path.write_text("\n".join(lines) + "\n")
    png_path = plot_tests(out_dir / f"table1-{scenario}-tests.png", scenario, test_rows)
    md_path = stem.with_suffix(".md")
    page = f"# Table I, {scenario}\n\n{meta['command']}\n\n{platform_line(meta['platform'])}\n\n"
    protocol = meta.get("protocol_delays_max_s", meta["delays_max_s"])
    if meta["delays_max_s"] != protocol:  # --sweep-up-to: the densest tests alone
        page += (f"Only the tests with delay_max {meta['delays_max_s'][0]:g} to {meta['delays_max_s'][-1]:g} s of "
                 f"the protocol's {protocol[0]:g} to {protocol[-1]:g} s: the paper's columns are for the whole "
                 "protocol, so ours compare with them only loosely.\n\n")
    if meta.get("share"):  # --share: a part of each test's jobs
        first_job, stop_job = meta["jobs"]
        page += (f"Share {meta['share'][0]}/{meta['share'][1]} of the protocol: {jobs_text(first_job, stop_job)} of "
                 f"each test's {meta['protocol_jobs']}, {meta['episodes_per_test']} of its "
                 f"{meta['protocol_episodes_per_test']} episodes; `crossway evaluate merge` joins the shares.\n\n")
    if meta.get("merged_from"):
        page += "Joined from runs over other jobs of each test:\n\n"
        for part in meta["merged_from"]:
            ran_on = platform_line(part.get("platform")).rstrip(".")
            page += (f"- {jobs_text(*part['jobs'])}, {part['episodes_per_test']} episodes per test, "
                     f"{part['wall_s']} s{workers_text(part)}: `{part['command']}` "
                     f"({ran_on[0].lower() + ran_on[1:]})\n")
        page += "\n"
        if meta.get("jobs_not_joined"):
            page += (f"The parts' protocol has {meta['jobs_not_joined']} more job(s) per test that no part holds: "
                     f"this is each test's first {meta['episodes_per_test']} episodes.\n\n")
    page += markdown(scenario, table)
    cut = sum(sum(t.get("cut_by_redraw", {}).values()) for t in tests)
    if cut:  # signs redrawn during the tests (hard)
        counted = sum(sum(c.values()) for t in tests for c in t["counts"].values())
        page += (f"\nEpisodes cut short by a sign redraw, not counted above: {cut} ({cut / (cut + counted):.1%} "
                 f"of those that ended; after a redraw the cars restart {meta.get('sign_change_restart')}).\n")
        uncut = pooled_rows([t.get("counts_uncuttable", {}) for t in tests])
        if uncut:
            cells = " / ".join(f"{uncut[s]['goal']:.3f}" if s in uncut else "-" for s in SIGNS)
            page += (f"Among the counted episodes that began at least the time limit before the next redraw, "
                     f"which no redraw could cut ({uncut['all']['episodes']}, all tests pooled), reaches per "
                     f"sign are {cells}.\n")
    page += f"\n## Per test\n\n![reach per test and sign]({png_path.name})\n\n" + markdown_tests(test_rows)
    page += markdown_braking(tests)
    if len(starts) > 1:
        page += ("\n## By how the episodes began\n\nreset: every lane's first episode in each job of at most "
                 f"{CHUNK_EPISODES} episodes, all lanes at once when the job's simulator starts; ")
        if "burst" in starts:  # signs redrawn during the tests (hard)
            when = ("when every lane starts at once" if meta.get("sign_change_restart") == "together"
                    else "each lane after its own random delay, a short one here")
            page += f"burst: within two steps of a sign redraw ({when}); "
        page += "staggered: every other episode. All tests pooled.\n\n" + markdown_starts(starts)
    md_path.write_text(page)
    return [json_path, csv_path, tests_csv_path, starts_csv_path, png_path, md_path]


def peek(out_dir: Path) -> str:
    """What a Table I run still going (or stopped) into ``out_dir`` has finished so far: its kept
    jobs (``--out/.partial``) per test and sign, and their average over the tests begun: a look
    at a long run before it ends, not its result (the densest tests may not have begun)."""
    import pickle

    from evaluation.parallel import PARTIAL_DIR

    folders = sorted((Path(out_dir) / PARTIAL_DIR).glob("table1-*"))
    if not folders:
        raise ValueError(f"{out_dir}: no Table I run in progress there (no {PARTIAL_DIR}/table1-*: "
                         "none began, or it has finished and written its outputs)")
    page = ""
    for folder in folders:
        parts = []
        for path in sorted(folder.glob("*.pkl")):
            try:
                parts.append(pickle.loads(path.read_bytes()))
            except Exception:  # noqa: BLE001 - being written, or unreadable: the run will redo it
                continue
        jobs = Counter(part["delay_max_s"] for part in parts)
        page += f"## {folder.name}: {len(parts)} job{'s' * (len(parts) != 1)} finished\n\n"
        if not parts:
            continue
        tests = sorted(merge_chunks(parts), key=lambda test: test["delay_max_s"])
        page += ("Jobs finished per test: " + ", ".join(f"{d:g} s: {jobs[d]}" for d in sorted(jobs)) + "\n\n"
                 + markdown_tests(per_test_rows(tests)) + "\nAveraged over these tests so far:\n\n")
        table = summarise(tests)
        page += "| | " + " | ".join(SIGNS) + " |\n|---|" + "---|" * len(SIGNS) + "\n"
        for key in (*OUTCOMES, "goal_stderr", "episodes"):
            cells = (("{:.3f}" if key != "episodes" else "{}").format(table[s][key]) if s in table else "-"
                     for s in SIGNS)
            name = COLUMN_NAMES.get(key, {"goal_stderr": "Reaches, standard error", "episodes": "Episodes"}.get(key))
            page += f"| {name} | " + " | ".join(cells) + " |\n"
        page += "\n"
    return page


# what every part of one protocol must share for ``merge_runs`` to join them (meta keys)
SAME_PROTOCOL = ("scenario", "seed", "delays_max_s", "protocol_delays_max_s", "sign_change_interval_s",
                 "sign_change_restart", *DriverOptions().record(), "scripted_sight_m", "scripted_sight_shift_m")


def jobs_of(meta: dict) -> tuple[int, int]:
    """The jobs [first, stop) of each test that a run's report holds; runs before --share ran
    every job of their --episodes."""
    if "jobs" in meta:
        return tuple(meta["jobs"])
    return 0, math.ceil(meta["episodes_per_test"] / CHUNK_EPISODES)


def merge_runs(reports: list[tuple[Path, dict]], out_dir: Path, command: str) -> dict:
    """Joins Table I runs of one protocol, each over other jobs of every test (``--share``, or a
    run of fewer --episodes and a share of more: a run's first jobs are the same episodes whatever
    its --episodes), into the report of one run over them all; refuses parts of other protocols,
    checkpoints or seeds, parts that overlap or leave a gap, before writing anything.
    ``reports``: (path, its parsed JSON) per part (``evaluation.shares.merge_reports``)."""
    parts = unpack(reports, "tests", "episodes_per_test", "Table I")
    check_same_protocol([(path, meta) for path, meta, _ in parts], SAME_PROTOCOL)
    parts.sort(key=lambda part: jobs_of(part[1]))
    ranges = [(path, jobs_of(meta), meta["episodes_per_test"]) for path, meta, _ in parts]
    stop = check_contiguous([(path, (first_job, stop_job), episodes != (stop_job - first_job) * CHUNK_EPISODES)
                             for path, (first_job, stop_job), episodes in ranges], per=" of each test")
    first = parts[0][1]
    by_delay: dict[float, list[dict]] = defaultdict(list)
    for _, _, tests in parts:
        for test in tests:
            by_delay[test["delay_max_s"]].append(test)
    results = merge_chunks([test for delay in first["delays_max_s"] for test in by_delay[delay]])
    table = summarise(results)
    episodes = sum(meta["episodes_per_test"] for _, meta, _ in parts)
    last_protocol_jobs = parts[-1][1].get("protocol_jobs", stop)  # runs before --share end their own protocol
    meta = merged_meta([(path, meta) for path, meta, _ in parts], SAME_PROTOCOL, command)
    meta.update({
        "episodes_per_test": episodes, "jobs": [0, stop], "protocol_jobs": stop,
        "protocol_episodes_per_test": episodes,
        # jobs of the parts' protocol that no part ran (a share left out): the report is then a shorter run
        "jobs_not_joined": max(0, last_protocol_jobs - stop),
        "merged_from": [part_record(path, m, jobs=list(jobs_of(m)), episodes_per_test=m["episodes_per_test"])
                        for path, m, _ in parts],
    })
    paths_written = write_outputs(out_dir, first["scenario"], results, table, meta)
    return {"table": table, "paths": paths_written, "meta": meta}


def plot_tests(path: Path, scenario: str, test_rows: list[dict]) -> Path:
    """The per-test reaches as a picture: one line per sign against the test's delay_max, a dot per
    test, and the paper's reach for that sign (its average over the tests) dashed in the same
    colour, so that the tests under the paper's figure stand out."""
    from crossway.plot import plot_curves

    series, styles = [], []
    paper = PAPER_TABLE1.get(scenario, {})
    delays = [r["delay_max_s"] for r in test_rows]
    x_range = (min(delays) - 5.0, max(delays) + 5.0)  # half a step beyond the tests: no dot on the frame
    for colour, sign in enumerate(SIGNS):
        rows = [r for r in test_rows if r["sign"] == sign and r["episodes"]]
        if not rows:
            continue
        xs = [r["delay_max_s"] for r in rows]
        series.append((f"{sign}: ours", xs, [r["goal"] for r in rows]))
        styles.append((colour, False))
        if sign in paper:
            series.append((f"{sign}: the paper (its average over the tests)", list(x_range), [paper[sign][0]] * 2))
            styles.append((colour, True))
    low = min(min(ys) for _, _, ys in series)
    y_range = (max(0.0, math.floor(low * 20 - 0.5) / 20), 1.0)  # on a 0.05 step, 0.025 or more under the lowest point
    return plot_curves(series, path, f"Table I, {scenario}: reach per test", "delay_max [s]", "reach",
                       y_range=y_range, styles=styles, markers=True, x_range=x_range)


def run_table1(scenario: str, checkpoint: str | None, episodes: int, workers: int, seed: int,
               out_dir: Path, command: str, scripted: DriverOptions | None = None,
               sign_restart: str | None = None, sweep_up_to_s: float | None = None,
               share: tuple[int, int] | None = None) -> dict:
    """The whole protocol in parallel workers (``scripted``: the scripted driver's options when
    ``checkpoint`` is None; ``sign_restart``: overrides the scenario's ``episodes.sign_change_restart``;
    ``sweep_up_to_s``: only the tests with delay_max up to it, each with the seeds it has in the
    whole protocol, so that their first chunks are the whole protocol's episodes; ``share``: (I, N),
    only the I-th of N parts of every test's jobs, for ``merge_runs`` to join); writes JSON, CSV
    and Markdown into ``out_dir``."""
    from simcore.scenario import load_scenario

    spec = load_scenario(scenario)
    if sign_restart is not None:
        spec = replace(spec, episodes=replace(spec.episodes, sign_change_restart=sign_restart))
    if checkpoint is not None:
        from evaluation.policy import check_checkpoint

        check_checkpoint(checkpoint, spec)  # refuse a bad checkpoint before starting workers
    scripted = scripted or DriverOptions()
    schedule = delay_schedule(spec.episodes.delay_max_s)
    if sweep_up_to_s is not None and not schedule[0] <= sweep_up_to_s:
        raise ValueError(f"--sweep-up-to must be at least the first test's delay_max, {schedule[0]:g} s; "
                         f"got {sweep_up_to_s:g}")
    # a test's seed is its place in the whole protocol: a shorter sweep runs the same tests
    tests = [TestSpec(spec, d, episodes, seed + i, checkpoint, scripted)
             for i, d in enumerate(schedule) if sweep_up_to_s is None or d <= sweep_up_to_s]
    jobs_per_test = len(chunks_of(tests[0]))
    first, stop = share_range(share, jobs_per_test, f"job(s) of at most {CHUNK_EPISODES} episodes per test")
    chunks = [chunk for t in tests for chunk in chunks_of(t)[first:stop]]
    run_episodes = sum(c.episodes for c in chunks_of(tests[0])[first:stop])  # per test
    started = time.monotonic()
    kept, salt, jobs = partial_dir(out_dir, f"table1-{spec.name}"), cache_salt(checkpoint), [(c,) for c in chunks]
    resumed = kept_jobs(run_test, jobs, kept, salt)  # finished chunks of an earlier run, stopped
    parts = run_parallel(run_test, jobs, run_episodes * len(tests), workers, f"table1 {spec.name}",
                         cache_dir=kept, salt=salt, sizes=[c.episodes for c in chunks])
    results = merge_chunks(parts)
    table = summarise(results)
    meta = {"scenario": spec.name, "checkpoint": checkpoint, "checkpoint_sha256": file_digest(checkpoint) or None,
            "episodes_per_test": run_episodes,
            # the jobs [first, stop) of each test's protocol_jobs (of CHUNK_EPISODES episodes each,
            # seeds: the test's + 1000 per job) that ran; all of them unless --share
            "jobs": [first, stop], "protocol_jobs": jobs_per_test, "protocol_episodes_per_test": episodes,
            "share": list(share) if share is not None else None,
            "delays_max_s": [t.delay_max_s for t in tests], "seed": seed, "workers": workers,
            # the whole protocol's tests; delays_max_s is fewer where --sweep-up-to cut the sweep
            "protocol_delays_max_s": schedule,
            # signs redrawn at this interval [s] (0: never) and how the cars restart after a redraw
            "sign_change_interval_s": spec.episodes.sign_change_interval_s,
            "sign_change_restart": spec.episodes.sign_change_restart,
            **(scripted.record() if checkpoint is None else dict.fromkeys(scripted.record())),
            # the view square's half-side and shift [m]: what "view" limits the scripted driver to
            "scripted_sight_m": 0.5 * spec.views.extent_m if scripted.sight == "view" else None,
            "scripted_sight_shift_m": spec.views.shift_m if scripted.sight == "view" else None,
            "wall_s": round(time.monotonic() - started, 1), "command": command,
            "jobs_from_an_earlier_run": resumed,  # wall_s then leaves out their time
            "platform": numeric_platform()}
    paths = write_outputs(out_dir, spec.name, results, table, meta)
    clear_partial(kept)
    return {"table": table, "paths": paths, "meta": meta}
