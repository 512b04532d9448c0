"""The paper's comparison with the TTC method (section "Comparison with TTC method", Fig. 5).

On hard, the ego starts from the stop-sign arm (south); traffic cars start from the two
adjacent arms (east and west, both lanes, main road without signs), go straight along their
route's centre and control their speed with the IDM. Traffic levels low, medium and high allow
at most 4, 8 and 12 traffic cars; each test raises the traffic's delay_max by 20 s. The TTC
agent and the learned policy drive the same episodes: the same seeds, the same traffic draws.

Half of each test's episodes start the ego on the inner lane (left or straight), half on the
outer lane (straight or right).
"""

from __future__ import annotations

import csv
import json
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from evaluation.parallel import cache_salt, clear_partial, file_digest, numeric_platform, partial_dir, run_parallel

TRAFFIC_LEVELS = {"low": 4, "medium": 8, "high": 12}
SIGNS = (("south", "stop"), ("east", "none"), ("west", "none"), ("north", "none"))
TRAFFIC_LANES = ("east_0", "east_1", "west_0", "west_1")
EGO_LANES = ("south_0", "south_1")
EGO_WAIT_S = (0.0, 2.0)  # the ego's wait between its episodes [s]


def ttc_setting(ego_lanes: tuple[str, ...], level: str, traffic_delay_max_s: float, observe: bool = True):
    """The test's simulator options (hard only): learners on ``ego_lanes`` of the stop-sign arm,
    at most TRAFFIC_LEVELS[level] IDM cars from the main road, each waiting 0 to
    ``traffic_delay_max_s`` before it starts again. Also the yield drill's (``--curriculum yield``)."""
    from simcore.simulator import SimConfig, TrafficConfig

    traffic = TrafficConfig(lanes=TRAFFIC_LANES, max_cars=TRAFFIC_LEVELS[level], delay_min_s=0.0,
                            delay_max_s=traffic_delay_max_s)
    return SimConfig(lanes=ego_lanes, signs=SIGNS, traffic=traffic, delay_min_s=EGO_WAIT_S[0],
                     delay_max_s=EGO_WAIT_S[1], observe=observe, start_all_at_reset=False)


@dataclass(frozen=True)
class TTCTest:
    driver: str  # "ttc" or "policy"
    level: str
    delay_max_s: float
    episodes: int
    seed: int
    threshold_s: float
    checkpoint: str | None


def run_ttc_test(test: TTCTest, progress=None) -> dict:
    """Episodes of one (driver, traffic level, delay) cell; counts end reasons of the ego."""
    import torch

    from evaluation.policy import PolicyDriver, load_policy
    from evaluation.ttc import TTCDriver
    from simcore.simulator import Simulator

    torch.set_num_threads(1)
    counts: Counter = Counter()
    policy = load_policy(test.checkpoint) if test.driver == "policy" else None
    per_lane = [test.episodes // 2 + test.episodes % 2, test.episodes // 2]
    for lane, episodes in zip(EGO_LANES, per_lane):
        if episodes == 0:
            continue
        config = ttc_setting((lane,), test.level, test.delay_max_s, observe=policy is not None)
        sim = Simulator("hard", config, seed=test.seed + (lane == EGO_LANES[1]))
        result = sim.reset()
        driver = PolicyDriver(sim, policy) if policy is not None else TTCDriver(sim, test.threshold_s)
        for _ in range(300):  # let traffic fill the road before the first ego episode counts
            result = sim.step(driver.act(result) if policy is not None else driver.act())
        done = 0
        while done < episodes:
            result = sim.step(driver.act(result) if policy is not None else driver.act())
            for episode in result.episodes:
                counts[episode.end_reason] += 1
                done += 1
                if progress is not None:
                    progress.put(1)
    total = sum(counts.values())
    return {"driver": test.driver, "level": test.level, "delay_max_s": test.delay_max_s, "episodes": total,
            "threshold_s": test.threshold_s, **{f"{k}_rate": counts.get(k, 0) / total
                                                for k in ("goal", "crash", "off_path", "time_over")}}


def cell_seed(seed: int, level_index: int, delay_index: int) -> int:
    """The seed of one (traffic level, delay) cell, the same in the sweep and in the comparison:
    a TTC cell at the chosen threshold is then the same episodes in both, and is run only once."""
    return seed + 100 * level_index + delay_index


PARTIAL_NAME = "ttc"  # the sweep's and the comparison's finished cells, until the outputs are written


def _run_all(tests: list[TTCTest], workers: int, label: str, out_dir: Path | None = None,
             checkpoint: str | None = None) -> list[dict]:
    """Every cell in workers; with ``out_dir`` each finished cell is kept for a rerun after a stop."""
    cache = partial_dir(out_dir, PARTIAL_NAME) if out_dir is not None else None
    return run_parallel(run_ttc_test, [(t,) for t in tests], sum(t.episodes for t in tests), workers, label,
                        cache_dir=cache, salt=cache_salt(checkpoint), sizes=[t.episodes for t in tests])


def sweep_thresholds(thresholds: list[float], episodes: int, delays: list[float], workers: int,
                     seed: int, out_dir: Path | None = None) -> tuple[float | None, list[dict]]:
    """The paper's choice: the threshold with the best reach rate among those with zero crashes
    (over every traffic level and delay). ``out_dir``: where ``run_comparison`` will write; its
    finished cells are kept there until then."""
    tests = [TTCTest("ttc", level, d, episodes, cell_seed(seed, j, i), thr, None)
             for thr in thresholds for j, level in enumerate(TRAFFIC_LEVELS) for i, d in enumerate(delays)]
    rows = _run_all(tests, workers, "ttc sweep", out_dir)
    best, best_reach = None, -1.0
    for thr in thresholds:
        mine = [r for r in rows if r["threshold_s"] == thr]
        crashes = sum(r["crash_rate"] * r["episodes"] for r in mine)
        reach = sum(r["goal_rate"] * r["episodes"] for r in mine) / sum(r["episodes"] for r in mine)
        if crashes == 0 and reach > best_reach:
            best, best_reach = thr, reach
    return best, rows


def run_comparison(checkpoint: str | None, threshold_s: float, episodes: int, delays: list[float],
                   workers: int, seed: int, out_dir: Path, command: str, sweep_rows: list[dict] = (),
                   share: tuple[int, int] | None = None) -> dict:
    """Both drivers on every (traffic level, delay) cell. ``sweep_rows``: rows of a sweep run with
    the same seed and episodes; its TTC cells at ``threshold_s`` are the same episodes, so they are
    taken as they are instead of being driven again. ``share``: (I, N), both drivers on only the
    I-th of N parts of the cells (in the order low traffic first, each by delay), for
    ``merge_runs`` to join."""
    from evaluation.shares import share_range

    drivers = ["ttc"] + (["policy"] if checkpoint is not None else [])
    if checkpoint is not None:
        from evaluation.policy import check_checkpoint
        from simcore.scenario import load_scenario

        check_checkpoint(checkpoint, load_scenario("hard"))  # the TTC test drives the built-in hard junction
    cells = [(j, level, i, d) for j, level in enumerate(TRAFFIC_LEVELS) for i, d in enumerate(delays)]
    first, stop = share_range(share, len(cells), "(traffic level, delay) cells")
    tests = [TTCTest(driver, level, d, episodes, cell_seed(seed, j, i), threshold_s, checkpoint)
             for driver in drivers for j, level, i, d in cells[first:stop]]
    swept = {(r["level"], r["delay_max_s"]): r for r in sweep_rows
             if r["driver"] == "ttc" and r["threshold_s"] == threshold_s and r["episodes"] == episodes}
    started = time.monotonic()
    # the learned policy's cells first: each takes several times a TTC cell, so the workers end
    # together and the progress line's rate (episodes per second) does not start on the fast ones
    to_run = sorted((t for t in tests if not (t.driver == "ttc" and (t.level, t.delay_max_s) in swept)),
                    key=lambda t: t.driver == "ttc")
    ran = dict(zip(to_run, _run_all(to_run, workers, "ttc comparison", out_dir, checkpoint) if to_run else []))
    rows = [ran[t] if t in ran else swept[(t.level, t.delay_max_s)] for t in tests]
    meta = {"checkpoint": checkpoint, "checkpoint_sha256": file_digest(checkpoint) or None, "threshold_s": threshold_s,
            "episodes_per_cell": episodes, "delays_max_s": delays, "levels": TRAFFIC_LEVELS, "seed": seed,
            "drivers": drivers,
            # the (level, delay) cells [first, stop) of the protocol's protocol_cells (levels in
            # order, each by delay) that both drivers ran; all of them unless --share
            "cells": [first, stop], "protocol_cells": len(cells), "share": list(share) if share is not None else None,
            "workers": workers, "wall_s": round(time.monotonic() - started, 1), "command": command,
            "ttc_cells_from_sweep": len(tests) - len(to_run), "platform": numeric_platform()}
    paths = write_outputs(out_dir, rows, meta)
    clear_partial(partial_dir(out_dir, PARTIAL_NAME))
    return {"rows": rows, "paths": paths, "meta": meta}


def write_outputs(out_dir: Path, rows: list[dict], meta: dict) -> list[Path]:
    """The comparison's CSV, JSON and, when the rows hold every cell, the paper's two figures."""
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path = out_dir / "ttc-comparison.csv"
    with open(csv_path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    json_path = out_dir / "ttc-comparison.json"
    json_path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    if meta["cells"] != [0, meta["protocol_cells"]]:  # a share: its figures would miss cells; merge draws them
        return [json_path, csv_path]
    return [json_path, csv_path, *draw_figures(rows, meta["threshold_s"], out_dir)]


# what every part of one comparison must share for ``merge_runs`` to join them
SAME_PROTOCOL = ("threshold_s", "episodes_per_cell", "delays_max_s", "levels", "seed", "drivers")


def cells_of(meta: dict, rows: list[dict]) -> tuple[int, int]:
    """The cells [first, stop) a report holds; reports before --share hold them all."""
    if "cells" in meta:
        return tuple(meta["cells"])
    return 0, len({(r["level"], r["delay_max_s"]) for r in rows})


def merge_runs(reports: list, out_dir: Path, command: str) -> dict:
    """Joins TTC comparisons over other cells (``--share``) into the report one run over them all
    writes: CSV, JSON and figures; refuses runs of other thresholds, sizes, seeds or checkpoints,
    and runs that overlap or leave a gap, before writing anything. ``reports``: (path, parsed
    JSON) per run."""
    from evaluation.shares import check_contiguous, check_same_protocol, merged_meta, part_record, unpack

    parts = unpack(reports, "rows", "threshold_s", "TTC comparison")
    for _, meta, rows in parts:  # reports before session 38 name no drivers
        meta.setdefault("drivers", [d for d in ("ttc", "policy") if any(r["driver"] == d for r in rows)])
    check_same_protocol([(path, meta) for path, meta, _ in parts], SAME_PROTOCOL)
    parts.sort(key=lambda part: cells_of(part[1], part[2]))
    stop = check_contiguous([(path, cells_of(meta, rows), False) for path, meta, rows in parts], noun="cell")
    drivers = parts[0][1]["drivers"]
    levels, delays = list(TRAFFIC_LEVELS), parts[0][1]["delays_max_s"]
    rows = sorted((row for _, _, part_rows in parts for row in part_rows),
                  key=lambda r: (drivers.index(r["driver"]), levels.index(r["level"]), delays.index(r["delay_max_s"])))
    meta = merged_meta([(path, meta) for path, meta, _ in parts], SAME_PROTOCOL, command)
    last_protocol_cells = parts[-1][1].get("protocol_cells", stop)
    meta.update({"cells": [0, stop], "protocol_cells": stop, "cells_not_joined": max(0, last_protocol_cells - stop),
                 "ttc_cells_from_sweep": sum(m.get("ttc_cells_from_sweep", 0) for _, m, _ in parts),
                 "merged_from": [part_record(path, m, cells=list(cells_of(m, r))) for path, m, r in parts]})
    paths = write_outputs(out_dir, rows, meta)
    return {"rows": rows, "paths": paths, "meta": meta}


def draw_figures(rows: list[dict], threshold_s: float, out_dir: Path) -> list[Path]:
    """The paper's two figures from comparison rows: reaches and time-overs against the traffic's
    delay_max, one colour per traffic level, the TTC agent dashed and the learned policy solid."""
    from crossway.plot import plot_curves

    drivers = [d for d in ("ttc", "policy") if any(r["driver"] == d for r in rows)]
    pictures = []
    for metric, title in (("goal_rate", "Reaches"), ("time_over_rate", "Time-overs")):
        series, styles = [], []
        for driver in drivers:
            for colour, level in enumerate(TRAFFIC_LEVELS):  # one colour per level; TTC dashed
                mine = sorted((r for r in rows if r["driver"] == driver and r["level"] == level),
                              key=lambda r: r["delay_max_s"])
                name = f"{'TTC' if driver == 'ttc' else 'learned'} ({level})"
                series.append((name, [r["delay_max_s"] for r in mine], [r[metric] for r in mine]))
                styles.append((colour, driver == "ttc"))
        path = out_dir / f"ttc-{metric.replace('_rate', '')}.png"
        plot_curves(series, path, f"{title} against traffic delay_max (TTC threshold {threshold_s:g} s)",
                    "traffic delay_max [s]", f"{title.lower()} (fraction)", (0.0, 1.0), styles=styles)
        pictures.append(path)
    return pictures
