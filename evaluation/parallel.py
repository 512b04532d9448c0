"""Run evaluation jobs in worker processes with one progress line for all of them."""

from __future__ import annotations

import multiprocessing
import queue
import sys
import time
from collections.abc import Callable, Sequence

BAR_WIDTH = 30  # characters of the progress bar


def run_parallel(function: Callable, jobs: Sequence[tuple], total: int, workers: int, label: str) -> list:
    """``function(*job, progress)`` for every job in ``workers`` spawned processes.

    Each job puts the number of episodes it finished on ``progress``; this process prints
    ``label: done/total episodes, elapsed, ETA`` on stderr: a bar redrawn at most twice a second
    on a terminal, a line every 30 s (and at the end) into a log file. Results come back in job
    order.
    """
    interactive = sys.stderr.isatty()
    interval = 0.5 if interactive else 30.0
    prefix = "\r" if interactive else ""
    started = time.monotonic()
    context = multiprocessing.get_context("spawn")  # workers start clean (Zenoh, torch threads)
    with context.Manager() as manager:
        progress = manager.Queue()
        with context.Pool(processes=max(1, min(workers, len(jobs)))) as pool:
            pending = pool.starmap_async(function, [(*job, progress) for job in jobs])
            done, shown = 0, -1.0
            while not pending.ready() or not progress.empty():
                try:
                    done += progress.get(timeout=0.5)
                except queue.Empty:
                    continue
                elapsed = time.monotonic() - started
                if elapsed - shown < interval and done < total:
                    continue
                shown = elapsed
                filled = int(BAR_WIDTH * done / max(total, 1))
                bar = "#" * filled + "-" * (BAR_WIDTH - filled)
                print(f"{prefix}{label} [{bar}] {done}/{total} episodes, {elapsed:5.0f} s, "
                      f"ETA {elapsed / done * (total - done):5.0f} s", end="" if interactive else "\n",
                      file=sys.stderr, flush=True)
            results = pending.get()
    if interactive:
        print(file=sys.stderr)
    return results
