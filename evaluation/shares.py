"""Running an evaluation protocol in shares (``--share I/N``) and joining the shares' reports.

Every protocol (Table I, the right-of-way test, the TTC comparison) is a fixed list of jobs, each
with its own seed: Table I's tests in 500-episode jobs, the right-of-way test's 150-episode jobs,
the TTC comparison's (traffic level, delay) cells. ``--share I/N`` runs the I-th of N contiguous
slices of that list, the jobs with the seeds they have in the whole protocol, so N machines (or N
sessions) can run one protocol and ``crossway evaluate merge`` can join their reports into the
very report one run over every job writes. Which protocol a report is of is told by its file name
(``KINDS``); each protocol's module does the joining of its counts.
"""

from __future__ import annotations

import json
from pathlib import Path

from simcore.controller import DriverOptions

# what a report older than a scripted driver option ran with: an option added later defaults to
# what the code did before it (``protocol_value``)
DRIVER_DEFAULTS = DriverOptions().record()

# report file patterns, by protocol: one of them in each output folder given to merge
KINDS = {"table1": "table1-*.json", "right-of-way": "right-of-way-*.json", "ttc": "ttc-comparison.json"}


def parse_share(text: str) -> tuple[int, int]:
    """``"I/N"`` -> (I, N): the I-th of N shares of a protocol's jobs (``share_range``)."""
    try:
        index, count = (int(x) for x in text.split("/"))
    except ValueError:
        raise ValueError(f"--share takes I/N, e.g. 2/3 (the second of three shares); got {text!r}") from None
    if not 1 <= index <= count:
        raise ValueError(f"--share I/N needs 1 <= I <= N; got {text!r}")
    return index, count


def share_range(share: tuple[int, int] | None, jobs: int, what: str) -> tuple[int, int]:
    """The jobs [first, stop) of a protocol of ``jobs`` jobs that share (I, N) runs (all of them for
    None): the I-th of N runs, each on its own machine, that together run every job once.
    ``what`` names the jobs in the refusal, e.g. "job(s) of at most 500 episodes per test"."""
    if share is None:
        return 0, jobs
    index, count = share
    if count > jobs:
        raise ValueError(f"--share {index}/{count}: the protocol has only {jobs} {what} to share out; "
                         f"use N <= {jobs}")
    return (index - 1) * jobs // count, index * jobs // count


def jobs_text(first: int, stop: int, noun: str = "job") -> str:
    """Jobs [first, stop) counted from 1, for people: "job 4", "jobs 4-6"."""
    return f"{noun} {stop}" if stop == first + 1 else f"{noun}s {first + 1}-{stop}"


def report_kind(path: Path) -> tuple[str, Path]:
    """(protocol, report file) of an output folder (its one report) or of a report file."""
    path = Path(path)
    if path.is_dir():
        found = [(kind, hit) for kind, pattern in KINDS.items() for hit in sorted(path.glob(pattern))]
        if len(found) != 1:
            names = ", ".join(KINDS.values())
            raise ValueError(f"{path}: expected one report ({names}) in the folder, found {len(found)}")
        return found[0]
    if not path.is_file():
        raise ValueError(f"{path}: no such file or folder")
    for kind, pattern in KINDS.items():
        if path.match(pattern):
            return kind, path
    report = read_report(path)  # a report renamed: told by what it holds
    meta = report.get("meta")
    if isinstance(meta, dict) and "tests" in report:
        return "table1", path
    if isinstance(meta, dict) and "rows" in report:
        return "ttc", path
    if "no_infraction" in report:
        return "right-of-way", path
    raise ValueError(f"{path}: not a report of a protocol that merges (Table I, right of way, TTC comparison)")


def read_report(path: Path) -> dict:
    try:
        report = json.loads(Path(path).read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not a JSON report ({error})") from None
    if not isinstance(report, dict):
        raise ValueError(f"{path}: not a report (a JSON object)")
    return report


def unpack(reports: list[tuple[Path, dict]], body: str, needed: str, name: str) -> list[tuple[Path, dict, list]]:
    """(path, meta, body) of each report of a protocol whose JSON is {"meta": ..., body: [...]};
    refuses one without them, or whose meta lacks ``needed``, as not a ``name`` report."""
    parts = []
    for path, report in reports:
        try:
            meta, rows = report["meta"], report[body]
            meta[needed]
        except (KeyError, TypeError) as error:
            raise ValueError(f"{path}: not a {name} report (no {error})") from None
        parts.append((path, meta, rows))
    return parts


def check_same_protocol(parts: list[tuple[Path, dict]], keys: tuple[str, ...]) -> None:
    """Refuses parts (report path, its meta) that differ in any of ``keys`` (as ``protocol_value``
    reads them) or in the checkpoint they evaluated (by SHA-256 where both record it, else by path)."""
    if len(parts) < 2:
        raise ValueError("merge needs two or more runs")
    first_path, first = parts[0]
    for path, meta in parts[1:]:
        for key in keys:
            ours, theirs = protocol_value(meta, key), protocol_value(first, key)
            if ours != theirs:
                raise ValueError(f"{path} and {first_path} ran other protocols: {key} {ours!r} against {theirs!r}")
        digests = (meta.get("checkpoint_sha256"), first.get("checkpoint_sha256"))
        if None not in digests and digests[0] != digests[1]:
            raise ValueError(f"{path} and {first_path} evaluated other checkpoints (SHA-256 {digests[0][:12]} "
                             f"against {digests[1][:12]})")
        if None in digests and meta.get("checkpoint") != first.get("checkpoint"):
            raise ValueError(f"{path} and {first_path} evaluated other checkpoints: {meta.get('checkpoint')!r} "
                             f"against {first.get('checkpoint')!r}")


def check_contiguous(ranges: list[tuple[Path, tuple[int, int], bool]], per: str = "", noun: str = "job") -> int:
    """Parts as (path, their jobs [first, stop), whether their last job is short), sorted by jobs:
    refuses parts that overlap, leave a gap or follow a short last job (a run that ended its own,
    shorter protocol). Returns the jobs joined (the last part's stop)."""
    stop = 0
    for index, (path, (first_job, stop_job), short_last) in enumerate(ranges):
        if first_job != stop:
            what = "overlap" if first_job < stop else "leave a gap"
            before = f"the runs before it {jobs_text(0, stop, noun)}" if stop else f"no run holds {noun} 1"
            raise ValueError(f"the runs {what}: {path} holds {jobs_text(first_job, stop_job, noun)}{per}, {before}")
        if short_last and index < len(ranges) - 1:
            raise ValueError(f"{path}: its last {noun} is shorter than the others, so it ends its protocol: it "
                             "cannot precede other jobs")
        stop = stop_job
    return stop


def protocol_value(meta: dict, key: str):
    """``meta[key]``; for a report older than a scripted driver option, the option's default
    (``DRIVER_DEFAULTS``), else None."""
    return meta[key] if key in meta else DRIVER_DEFAULTS.get(key)


def merged_meta(parts: list[tuple[Path, dict]], keys: tuple[str, ...], command: str) -> dict:
    """What a joined report's meta shares with its parts, and what it adds up from them."""
    first = parts[0][1]
    meta = {key: protocol_value(first, key) for key in keys}
    meta.update({
        "checkpoint": first.get("checkpoint"),
        "checkpoint_sha256": next((m.get("checkpoint_sha256") for _, m in parts if m.get("checkpoint_sha256")), None),
        "share": None,
        # the most worker processes any one part ran at once (each part's own is in merged_from): the
        # parts often ran on machines of their own, so a sum would claim a parallelism no run had
        "workers": max((m.get("workers") or 0 for _, m in parts), default=0),
        "wall_s": round(sum(m.get("wall_s", 0.0) or 0.0 for _, m in parts), 1),  # the parts' own, added up
        "command": command,
        "jobs_from_an_earlier_run": sum(m.get("jobs_from_an_earlier_run", 0) or 0 for _, m in parts),
        # the first part's machine that is on record (reports before session 28 have none)
        "platform": next((m.get("platform") for _, m in parts if m.get("platform")), None),
    })
    return meta


def part_record(path: Path, meta: dict, **size) -> dict:
    """One part of a joined report, for its ``merged_from``: where it is, how it ran (command, wall
    time [s], worker processes, machine) and which part of the protocol it holds (``size``: its
    jobs or cells, and episodes)."""
    return {"path": str(path), "command": meta.get("command"), **size, "wall_s": meta.get("wall_s"),
            "workers": meta.get("workers"), "platform": meta.get("platform")}


def workers_text(part: dict) -> str:
    """The words ' on N workers' for a part of a joined report that records them (parts before
    session 43 do not)."""
    workers = part.get("workers")
    return f" on {workers} worker{'s' if workers != 1 else ''}" if workers else ""


def merge_reports(paths: list[Path], out_dir: Path, command: str) -> dict:
    """Joins the reports of runs over other jobs of one protocol into the report one run over all
    their jobs writes (in ``out_dir``); refuses, before writing anything, runs of two protocols
    and whatever the protocol's own join refuses. Returns the protocol's kind and its report."""
    found = [report_kind(path) for path in paths]
    kinds = {kind for kind, _ in found}
    if len(kinds) > 1:
        raise ValueError(f"the runs are of different protocols ({', '.join(sorted(kinds))}): merge joins one")
    kind = kinds.pop()
    reports = [(path, read_report(path)) for _, path in found]
    if kind == "table1":
        from evaluation.table1 import merge_runs
    elif kind == "right-of-way":
        from evaluation.right_of_way import merge_runs
    else:
        from evaluation.ttc_test import merge_runs
    return {"kind": kind, **merge_runs(reports, Path(out_dir), command)}
