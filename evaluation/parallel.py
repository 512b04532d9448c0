"""Run evaluation jobs in worker processes with one progress line for all of them.

The workers never outlive the command: SIGTERM (a scheduler's stop, ``kill``) and Ctrl-C end
the pool before the command exits, and a worker whose parent died anyway (SIGKILL, a crash)
notices within ``ORPHAN_CHECK_S`` and exits, instead of driving its chunk to the end on a
core nobody is waiting for.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence

BAR_WIDTH = 30  # characters of the progress bar
ORPHAN_CHECK_S = 1.0  # how often a worker checks that the command that started it still runs [s]

_progress = None  # in a worker: the queue its jobs report finished episodes on


def _start_worker(progress, parent_pid: int) -> None:
    global _progress
    _progress = progress
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the parent decides
    threading.Thread(target=_exit_when_orphaned, args=(parent_pid,), daemon=True).start()


def _exit_when_orphaned(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(ORPHAN_CHECK_S)
    os._exit(1)


def _run_job(function: Callable, job: tuple):
    return function(*job, _progress)


def _stop_on_sigterm(*_) -> None:
    raise SystemExit(128 + signal.SIGTERM)  # unwinds the pool's context: its workers are terminated


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
    progress = context.Queue()
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _stop_on_sigterm) if in_main_thread else None
    try:
        with context.Pool(processes=max(1, min(workers, len(jobs))), initializer=_start_worker,
                          initargs=(progress, os.getpid())) as pool:
            pending = pool.starmap_async(_run_job, [(function, job) for job in jobs])
            done, shown = 0, -1.0
            while not pending.ready() or done < total:
                try:
                    done += progress.get(timeout=0.5)
                except queue.Empty:
                    if pending.ready():
                        break  # every job has returned and reported
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
    finally:
        if in_main_thread:
            signal.signal(signal.SIGTERM, previous)
        progress.close()
    if interactive:
        print(file=sys.stderr)
    return results
