"""The right-of-way test's infraction check (paper, "Testing the Right of Way Rule", Table II).

An agent commits an infraction when it enters a conflict area before an agent that has
priority over it there and that will also cross it. Precisely, for every ordered pair (a, b) of
agents of one episode whose routes conflict (``PriorityTable.conflict``):

- b has priority over a by the rule alone (``PriorityTable`` with both still short of the
  zone): b's sign outranks a's, or the signs are equal and b comes from a's right (or the
  opposite-arm and tie-break rules of ``simcore.rightofway``);
- a *enters* the area at the first step its front reaches the zone's start on its route,
  ``s + length/2 >= zone_start``; b likewise on its own route;
- a's infraction: b has priority, b enters at some step of the episode, and a entered strictly
  earlier. If b never enters (it ended before), nobody was wronged: no infraction.

An episode is "no infraction" when no ordered pair has one.

Each infraction is also sorted by what the offender could have known (``seen_in_time``): whether
the car it wronged could show in its view (the scenario's square) at some step when it
could still have stopped short of the zone braking at ``MAX_ACCELERATION``. An infraction the
offender could not have seen in time could not have been avoided, at the speeds it drove, by
reacting to its views; only slowing down before anything showed would have.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from evaluation.shares import jobs_text, workers_text
from simcore.controller import DriverOptions
from simcore.dynamics import DT, MAX_ACCELERATION, VEHICLE_LENGTH
from simcore.rewards import END_REASON_NAMES, EndReason
from simcore.rightofway import PriorityTable
from simcore.views import may_show

CRASH = END_REASON_NAMES[EndReason.CRASH]

if TYPE_CHECKING:
    from simcore.scenario import ScenarioSpec
    from simcore.simulator import SimConfig, Simulator


@dataclass(frozen=True)
class Infraction:
    offender: int  # agent index
    wronged: int  # the agent with priority that entered later
    offender_entry_step: int
    wronged_entry_step: int


def entry_step(s_track: np.ndarray, zone_start: float) -> int | None:
    """First step at which a car's front reaches ``zone_start``; ``s_track`` [T] is NaN when absent."""
    reached = np.flatnonzero(s_track + 0.5 * VEHICLE_LENGTH >= zone_start)
    return int(reached[0]) if len(reached) else None


def find_infractions(table: PriorityTable, routes: np.ndarray, signs: np.ndarray,
                     s_tracks: np.ndarray) -> list[Infraction]:
    """Infractions of one episode: ``routes`` [N], ``signs`` [N] and ``s_tracks`` [N, T] (arc
    length of each agent's centre per step, NaN when it is not on the road)."""
    n = len(routes)
    start = np.full(n, -1e9)  # priority by the rule: evaluated with every car far from the zones
    higher = table.higher(np.asarray(routes), start, np.asarray(signs))
    found = []
    for a in range(n):
        for b in range(n):
            if a == b or not higher[a, b]:
                continue
            a_entry = entry_step(s_tracks[a], table.zone_start[routes[a], routes[b]])
            b_entry = entry_step(s_tracks[b], table.zone_start[routes[b], routes[a]])
            if a_entry is not None and b_entry is not None and a_entry < b_entry:
                found.append(Infraction(a, b, a_entry, b_entry))
    return found


@dataclass(frozen=True)
class Pose:
    """One car's track through an episode, per step [T]; NaN while it is not on the road."""

    x: np.ndarray  # [m]
    y: np.ndarray  # [m]
    heading: np.ndarray  # [rad]
    s: np.ndarray  # arc length of its centre on its route [m]
    speed: np.ndarray  # [m/s]

    def until(self, step: int) -> Pose:
        """The track up to and including ``step``."""
        return Pose(self.x[: step + 1], self.y[: step + 1], self.heading[: step + 1], self.s[: step + 1],
                    self.speed[: step + 1])


def in_view(ego: Pose, other: Pose, extent_m: float, shift_m: float) -> np.ndarray:
    """[T] bool: some of ``other``'s body may show in ``ego``'s view square (side ``extent_m``,
    centre ``shift_m`` ahead of the car; paper, "Environment": 50 x 50 m; ``simcore.views.may_show``).
    Generous on purpose: an infraction is excused as unseen only if the car could not show at all."""
    return may_show(ego.x, ego.y, ego.heading, other.x, other.y, extent_m, shift_m)


def seen_in_time(offender: Pose, wronged: Pose, zone_start: float, entry: int, extent_m: float,
                 shift_m: float, max_braking_mps2: float = MAX_ACCELERATION) -> bool:
    """Whether ``wronged`` may show in ``offender``'s view at some step up to ``entry`` at which the
    offender could still stop before ``zone_start`` (its front's room >= v^2 / (2 b), b =
    ``max_braking_mps2``): the infraction was avoidable by a driver of those views."""
    offender, wronged = offender.until(entry), wronged.until(entry)
    room = zone_start - (offender.s + 0.5 * VEHICLE_LENGTH)
    with np.errstate(invalid="ignore"):
        could_stop = room >= offender.speed ** 2 / (2.0 * max_braking_mps2)
    return bool(np.any(could_stop & in_view(offender, wronged, extent_m, shift_m)))


@dataclass(frozen=True)
class SynchronisedEpisode:
    """What one right-of-way episode leaves to judge: every agent's route, sign, track and end."""

    sim: Simulator  # the simulator it ran in (its priority table and views)
    routes: np.ndarray  # [N]
    signs: np.ndarray  # [N]
    tracks: np.ndarray  # [5, N, T]: x, y, heading, s, speed per agent and step (NaN once ended)
    end_reasons: list[str]  # [N]; "" for a car still driving when the time limit stopped the episode

    def pose(self, agent: int) -> Pose:
        return Pose(*self.tracks[:, agent])

    def infractions(self) -> list[Infraction]:
        return find_infractions(self.sim.priority, self.routes, self.signs, self.tracks[3])

    def seen_in_time(self, infraction: Infraction, extent_m: float | None = None) -> bool:
        """``seen_in_time`` for one infraction, in the scenario's view (or a square of side ``extent_m``)."""
        views = self.sim.spec.views
        zone = self.sim.priority.zone_start[self.routes[infraction.offender], self.routes[infraction.wronged]]
        return seen_in_time(self.pose(infraction.offender), self.pose(infraction.wronged), zone,
                            infraction.offender_entry_step, views.extent_m if extent_m is None else extent_m,
                            views.shift_m)


def synchronised_config(observe: bool) -> SimConfig:
    """The test's simulator options: every lane starts at once, with one shared current and one
    shared target speed, nobody starts again, signs stay as drawn (paper, "Testing the Right of
    Way Rule"); ``observe`` renders the views a policy needs."""
    from simcore.simulator import SimConfig

    return SimConfig(start_all_at_reset=True, delay_min_s=1e9, delay_max_s=1e9, sign_change_interval_s=0.0,
                     equal_speeds=True, observe=observe)


def drive_episode(sim: Simulator, act, result) -> SynchronisedEpisode:
    """Drive ``sim``, just reset (``result`` from ``reset()``), until every agent has ended or the
    time limit; ``act(result)`` gives the actions of each step."""
    n = sim.num_slots
    limit = int(sim.time_limit_s / DT) + 2
    routes, signs = sim.route[:n].copy(), sim.sign[:n].copy()
    tracks = np.full((5, n, limit), np.nan)
    tracks[:, :, 0] = sim.x[:n], sim.y[:n], sim.heading[:n], sim.s[:n], sim.speed[:n]
    end_reasons = [""] * n
    step = 0
    while sim.learners_present.any() and step + 1 < limit:
        result = sim.step(act(result))
        step += 1
        for row, values in enumerate((sim.x, sim.y, sim.heading, sim.s, sim.speed)):
            tracks[row, result.acted, step] = values[:n][result.acted]
        for summary in result.episodes:
            end_reasons[summary.slot] = summary.end_reason
    return SynchronisedEpisode(sim, routes, signs, tracks[:, :, : step + 1], end_reasons)


# -- the test itself ---------------------------------------------------------------------------------

PAPER_TABLE2 = {"easy": 0.985, "medium": 0.990, "hard": 0.863}  # "No infraction" fractions (Table II)


def run_episodes(scenario: ScenarioSpec | str, checkpoint: str | None, episodes: int, seed: int,
                 scripted: DriverOptions | None = None, progress=None) -> dict:
    """Synchronised episodes: every lane starts at once with a random route and sign, all cars at
    the same current and target speed; an episode ends when every car has ended (paper,
    "Testing the Right of Way Rule"). Without a checkpoint the scripted driver drives, with the
    options ``scripted`` (``simcore.controller.DriverOptions``). Runs in a worker process."""
    import torch

    from evaluation.policy import PolicyDriver, load_policy
    from simcore.controller import scripted_driver
    from simcore.simulator import Simulator

    torch.set_num_threads(1)
    sim = Simulator(scenario, synchronised_config(observe=checkpoint is not None), seed=seed)
    policy = load_policy(checkpoint) if checkpoint is not None else None
    clean = clean_of_seen = 0  # episodes without infractions / without any the offender saw in time
    anatomy = {"seen_in_time": 0, "offender_crashed": 0}  # infractions by kind
    infraction_counts = []
    end_reasons: dict[str, int] = {}
    for _ in range(episodes):
        result = sim.reset()
        if policy is not None:
            driver = PolicyDriver(sim, policy)
        else:
            driver = scripted_driver(sim, scripted)
        episode = drive_episode(sim, lambda r: driver.act(r) if policy is not None else driver.act(), result)
        for reason in filter(None, episode.end_reasons):  # "" for a car still driving at the time limit
            end_reasons[reason] = end_reasons.get(reason, 0) + 1
        found = episode.infractions()
        seen = [episode.seen_in_time(f) for f in found]
        infraction_counts.append(len(found))
        anatomy["seen_in_time"] += sum(seen)
        anatomy["offender_crashed"] += sum(episode.end_reasons[f.offender] == CRASH for f in found)
        clean += not found
        clean_of_seen += not any(seen)
        if progress is not None:
            progress.put(1)
    return {"episodes": episodes, "no_infraction": clean, "no_seen_infraction": clean_of_seen,
            "infractions_per_episode": infraction_counts, "anatomy": anatomy, "end_reasons": end_reasons}


CHUNK_EPISODES = 150  # episodes per job (300 on two workers split as before session 28: seeds S, S + 1000)


def chunk_sizes(episodes: int) -> list[int]:
    """The test's jobs: ``episodes`` in chunks of ``CHUNK_EPISODES``, the last one shorter."""
    return [min(CHUNK_EPISODES, episodes - start) for start in range(0, episodes, CHUNK_EPISODES)]


def run_right_of_way(scenario: str, checkpoint: str | None, episodes: int, workers: int, seed: int,
                     out_dir, command: str, scripted: DriverOptions | None = None,
                     share: tuple[int, int] | None = None) -> dict:
    """The whole test in parallel workers (``share``: (I, N), only the I-th of N parts of its jobs,
    for ``merge_runs`` to join); writes JSON, CSV and Markdown into ``out_dir``."""
    import time
    from pathlib import Path

    from evaluation.parallel import (cache_salt, clear_partial, file_digest, kept_jobs, numeric_platform,
                                     partial_dir, run_parallel)
    from evaluation.shares import share_range
    from simcore.scenario import load_scenario

    spec = load_scenario(scenario)
    if checkpoint is not None:
        from evaluation.policy import check_checkpoint

        check_checkpoint(checkpoint, spec)
    # jobs of at most CHUNK_EPISODES episodes, each with its own simulator and seed: the numbers do
    # not depend on --workers, and a rerun after a stop takes the chunks that had finished
    sizes = chunk_sizes(episodes)
    first, stop = share_range(share, len(sizes), f"job(s) of at most {CHUNK_EPISODES} episodes")
    scripted = scripted or DriverOptions()
    jobs = [(spec, checkpoint, n, seed + 1000 * i, scripted) for i, n in enumerate(sizes)][first:stop]
    workers = max(1, min(workers, len(jobs)))
    started = time.monotonic()
    kept, salt = partial_dir(Path(out_dir), f"right-of-way-{spec.name}"), cache_salt(checkpoint)
    resumed = kept_jobs(run_episodes, jobs, kept, salt)
    ran = sum(sizes[first:stop])
    parts = run_parallel(run_episodes, jobs, ran, workers, f"right-of-way {spec.name}", cache_dir=kept,
                         salt=salt, sizes=sizes[first:stop])
    end_reasons: dict[str, int] = {}
    for part in parts:
        for reason, count in part["end_reasons"].items():
            end_reasons[reason] = end_reasons.get(reason, 0) + count
    counts = {"episodes": ran,
              "no_infraction_episodes": sum(p["no_infraction"] for p in parts),
              "no_seen_infraction_episodes": sum(p["no_seen_infraction"] for p in parts),
              "infractions": sum(sum(p["infractions_per_episode"]) for p in parts),
              "infractions_seen_in_time": sum(p["anatomy"]["seen_in_time"] for p in parts),
              "infractions_offender_crashed": sum(p["anatomy"]["offender_crashed"] for p in parts),
              "agent_end_reasons": end_reasons}
    meta = {"scenario": spec.name, "view_extent_m": spec.views.extent_m, "view_shift_m": spec.views.shift_m,
            "checkpoint": checkpoint, "checkpoint_sha256": file_digest(checkpoint) or None,
            **(scripted.record() if checkpoint is None else dict.fromkeys(scripted.record())),
            "seed": seed, "workers": workers, "episodes_per_job": CHUNK_EPISODES,
            # the jobs [first, stop) of the protocol's protocol_jobs (seeds: --seed + 1000 per job) that
            # ran; all of them unless --share
            "jobs": [first, stop], "protocol_jobs": len(sizes), "protocol_episodes": episodes,
            "share": list(share) if share is not None else None,
            "wall_s": round(time.monotonic() - started, 1), "command": command,
            "jobs_from_an_earlier_run": resumed, "platform": numeric_platform()}
    summary = write_outputs(Path(out_dir), counts, meta)
    clear_partial(kept)
    return summary


def write_outputs(out_dir, counts: dict, meta: dict) -> dict:
    """The test's JSON (``counts`` and ``meta`` in one flat record, with the rates), CSV and
    Markdown from its counts; returns the record with the table and the paths written."""
    import json

    from evaluation.parallel import platform_line

    episodes, scenario = counts["episodes"], meta["scenario"]
    rate = counts["no_infraction_episodes"] / episodes
    paper = PAPER_TABLE2.get(scenario)
    summary = {"scenario": scenario, "episodes": episodes, "no_infraction": rate,
               "infraction": 1.0 - rate, "no_infraction_stderr": (rate * (1.0 - rate) / episodes) ** 0.5,
               "paper_no_infraction": paper,
               # the same test excusing infractions against a car the offender could not see in time
               "no_seen_infraction": counts["no_seen_infraction_episodes"] / episodes,
               **counts, **meta}
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = out_dir / f"right-of-way-{scenario}"
    stem.with_suffix(".json").write_text(json.dumps(summary, indent=2))
    infractions = summary["infractions"]
    stem.with_suffix(".csv").write_text(
        "scenario,episodes,no_infraction,infraction,no_infraction_stderr,paper_no_infraction,no_seen_infraction,"
        "infractions,infractions_seen_in_time,infractions_offender_crashed\n"
        f"{scenario},{episodes},{summary['no_infraction']:.4f},{summary['infraction']:.4f},"
        f"{summary['no_infraction_stderr']:.4f},{'' if paper is None else paper},{summary['no_seen_infraction']:.4f},"
        f"{infractions},{summary['infractions_seen_in_time']},{summary['infractions_offender_crashed']}\n")
    table = ("| | ours | paper |\n|---|---|---|\n"
             f"| No infraction | {summary['no_infraction']:.3f} | {'-' if paper is None else f'{paper:.3f}'} |\n"
             f"| Infraction | {summary['infraction']:.3f} | {'-' if paper is None else f'{1 - paper:.3f}'} |\n"
             f"| No infraction, standard error | {summary['no_infraction_stderr']:.3f} | - |\n"
             f"| No infraction the offender saw in time | {summary['no_seen_infraction']:.3f} | - |\n"
             f"| Infractions (all episodes): seen in time / offender crashed / all | "
             f"{summary['infractions_seen_in_time']} / {summary['infractions_offender_crashed']} / {infractions}"
             " | - |\n")
    page = f"# Right-of-way test (Table II), {scenario}\n\n{meta['command']}\n\n{platform_line(meta['platform'])}\n\n"
    if meta.get("share"):
        page += (f"Share {meta['share'][0]}/{meta['share'][1]} of the test: {jobs_text(*meta['jobs'])} of its "
                 f"{meta['protocol_jobs']}, {episodes} of its {meta['protocol_episodes']} episodes; "
                 "`crossway evaluate merge` joins the shares.\n\n")
    if meta.get("merged_from"):
        page += "Joined from runs over other jobs of the test:\n\n" + merged_from_lines(meta["merged_from"]) + "\n"
        if meta.get("jobs_not_joined"):
            page += (f"The parts' test has {meta['jobs_not_joined']} more job(s) that no part holds: this is its "
                     f"first {episodes} episodes.\n\n")
    stem.with_suffix(".md").write_text(page + table)
    summary["markdown"] = table
    summary["paths"] = [str(stem.with_suffix(x)) for x in (".json", ".csv", ".md")]
    return summary


def merged_from_lines(parts: list[dict]) -> str:
    """The parts of a joined report, one Markdown list item each: jobs, size, time, command, machine."""
    from evaluation.parallel import platform_line

    lines = ""
    for part in parts:
        ran_on = platform_line(part.get("platform")).rstrip(".")
        lines += (f"- {jobs_text(*part['jobs'])}, {part['episodes']} episodes, {part['wall_s']} s{workers_text(part)}: "
                  f"`{part['command']}` ({ran_on[0].lower() + ran_on[1:]})\n")
    return lines


# what every part of one test must share for ``merge_runs`` to join them
SAME_PROTOCOL = ("scenario", "seed", "episodes_per_job", "view_extent_m", "view_shift_m", *DriverOptions().record())
COUNTS = ("infractions", "infractions_seen_in_time", "infractions_offender_crashed")


def jobs_of(record: dict) -> tuple[int, int]:
    """The jobs [first, stop) a report holds; runs before --share ran every job of their --episodes."""
    if "jobs" in record:
        return tuple(record["jobs"])
    return 0, len(chunk_sizes(record["episodes"]))


def merge_runs(reports: list, out_dir, command: str) -> dict:
    """Joins right-of-way runs of one test over other jobs (``--share``, or a run of fewer
    --episodes: its jobs are the first ones) into the report one run over them all writes;
    refuses runs of other tests, seeds or checkpoints, and runs that overlap or leave a gap, before
    writing anything. ``reports``: (path, parsed JSON) per run."""
    from pathlib import Path

    from evaluation.shares import check_contiguous, check_same_protocol, merged_meta, part_record

    for path, record in reports:
        if not all(key in record for key in ("episodes", "no_infraction", *COUNTS)):
            raise ValueError(f"{path}: not a right-of-way report")
    check_same_protocol(reports, SAME_PROTOCOL)
    parts = sorted(reports, key=lambda part: jobs_of(part[1]))
    stop = check_contiguous([(path, jobs_of(r), r["episodes"] % r.get("episodes_per_job", CHUNK_EPISODES) != 0)
                             for path, r in parts])
    counts = {"episodes": sum(r["episodes"] for _, r in parts),
              # reports before session 38 hold rates alone: rate x episodes is the count they came from
              "no_infraction_episodes": sum(r.get("no_infraction_episodes", round(r["no_infraction"] * r["episodes"]))
                                            for _, r in parts),
              "no_seen_infraction_episodes": sum(r.get("no_seen_infraction_episodes",
                                                       round(r["no_seen_infraction"] * r["episodes"]))
                                                 for _, r in parts),
              **{key: sum(r[key] for _, r in parts) for key in COUNTS}}
    reasons: dict[str, int] = {}
    for _, r in parts:
        for reason, count in r.get("agent_end_reasons", {}).items():
            reasons[reason] = reasons.get(reason, 0) + count
    counts["agent_end_reasons"] = reasons
    meta = merged_meta(parts, SAME_PROTOCOL, command)
    last_protocol_jobs = parts[-1][1].get("protocol_jobs", stop)
    meta.update({"jobs": [0, stop], "protocol_jobs": stop, "protocol_episodes": counts["episodes"],
                 "jobs_not_joined": max(0, last_protocol_jobs - stop),
                 "merged_from": [part_record(path, r, jobs=list(jobs_of(r)), episodes=r["episodes"])
                                 for path, r in parts]})
    summary = write_outputs(Path(out_dir), counts, meta)
    return {"summary": summary, "paths": summary["paths"], "meta": meta}
