"""Run evaluation jobs in worker processes with one progress line for all of them.

The workers never outlive the command: SIGTERM (a scheduler's stop, ``kill``) and Ctrl-C end
the pool before the command exits, and a worker whose parent died anyway (SIGKILL, a crash)
notices within ``ORPHAN_CHECK_S`` and exits, instead of driving its chunk to the end on a
core nobody is waiting for.

Nothing finished is lost: with a ``cache_dir`` every job's result is kept there as soon as it
returns, and the same command run again (same jobs, same checkpoint file) takes those results
instead of running the jobs again. The caller removes the folder once its outputs are written.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import pickle
import queue
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from crossway.stopping import StopRequest, stop_handlers

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


def job_key(function: Callable, job: tuple, salt: str = "") -> str:
    """A job's name in a cache folder: the function, the job's arguments (their ``repr``: every
    job argument is a dataclass, tuple or plain value) and ``salt`` (e.g. the checkpoint's digest)."""
    text = f"{function.__module__}.{function.__qualname__}\n{salt}\n{job!r}"
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def file_digest(path: str | Path | None) -> str:
    """SHA-256 of a file's bytes ("" for None): a cache salt that changes when the checkpoint does."""
    if path is None:
        return ""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


PARTIAL_DIR = ".partial"  # in an output folder: finished jobs of a command that has not finished yet


def partial_dir(out_dir: Path, name: str) -> Path:
    """Where command ``name`` keeps its finished jobs until it has written its outputs."""
    return out_dir / PARTIAL_DIR / name


def kept_jobs(function: Callable, jobs: Sequence[tuple], cache_dir: Path, salt: str = "") -> int:
    """How many of ``jobs`` an earlier run of the same command finished and kept in ``cache_dir``."""
    return sum((cache_dir / f"{job_key(function, job, salt)}.pkl").is_file() for job in jobs)


def clear_partial(path: Path) -> None:
    """Remove a command's kept jobs (its outputs are written), and ``.partial`` once empty."""
    shutil.rmtree(path, ignore_errors=True)
    try:
        path.parent.rmdir()
    except OSError:
        pass  # another command's jobs are still kept there, or it is gone already


# the packages whose code decides an evaluation job's result (simulator, networks, drivers, protocols)
RESULT_PACKAGES = ("simcore", "algo", "evaluation")


def source_digest(roots: Sequence[Path]) -> str:
    """SHA-256 over the paths and bytes of every ``.py`` file under ``roots``: changes with the code
    (a development checkout keeps one version number through every change)."""
    digest = hashlib.sha256()
    for root in roots:
        for path in sorted(Path(root).rglob("*.py")):
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


_code_digest: str | None = None

# environment variables that choose the float kernels torch, MKL and oneDNN run (their instruction set)
KERNEL_VARIABLES = ("ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS", "MKL_CBWR", "ONEDNN_MAX_CPU_ISA",
                    "DNNL_MAX_CPU_ISA")
# CPU features that change which kernels run, as /proc/cpuinfo names them
KERNEL_CPU_FLAGS = ("avx", "avx2", "fma", "avx512f", "avx512_vnni", "avx512_bf16", "amx_tile")


# MKL's code path ("conditional numerical reproducibility") that --portable-kernels asks for: MKL
# documents the same bits on every Intel CPU with AVX2 (since 2013) at the same thread count; on
# other CPUs it may keep its usual dispatch
PORTABLE_MKL_BRANCH = "AVX2"


def use_portable_kernels() -> None:
    """Make the worker processes started from now on multiply on MKL's ``PORTABLE_MKL_BRANCH`` code
    path instead of the fastest one for this CPU, so that a seed gives the same episodes on every
    machine with it (``crossway evaluate --portable-kernels``). MKL reads ``MKL_CBWR`` when it
    starts: it holds for the spawned workers, not for this process's torch if already loaded.

    Refuses (ValueError) where the environment already asks MKL for another code path: the user's
    choice is not overwritten silently, and the JSON would not say which of the two was meant."""
    chosen = os.environ.get("MKL_CBWR", "")
    if chosen and chosen != PORTABLE_MKL_BRANCH:
        raise ValueError(f"--portable-kernels sets MKL_CBWR={PORTABLE_MKL_BRANCH}, but the environment already "
                         f"sets MKL_CBWR={chosen}: unset it (or drop --portable-kernels to keep it)")
    os.environ["MKL_CBWR"] = PORTABLE_MKL_BRANCH


def numeric_platform() -> dict:
    """What, besides the code, the checkpoint and the seed, decides an evaluation's numbers: the
    library versions and the float kernels they pick for this CPU. A policy's actions differ in the
    last bits between instruction sets (AVX2 against AVX-512 matrix products), an episode follows
    the first difference and the counts drift by about a standard error (docs/evaluation.md,
    "Same numbers on another machine"): an evaluation records this, and a kept job's result is
    taken only on the same platform."""
    import platform

    import numpy
    import torch

    flags: set[str] = set()
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "flags" and not flags:
                flags = set(value.split())
            elif key.strip() == "model name":
                model = value.strip()
    except OSError:
        pass  # not Linux: the model from platform, no flags
    return {"python": platform.python_version(), "torch": torch.__version__, "numpy": numpy.__version__,
            "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(), "cpu": model,
            "cpu_flags": [f for f in KERNEL_CPU_FLAGS if f in flags],
            "kernel_variables": {name: os.environ[name] for name in KERNEL_VARIABLES if name in os.environ}}


def platform_line(platform: dict | None) -> str:
    """``numeric_platform()`` in one line for a results page: what the numbers ran on (None: a
    report from before session 28, which did not record it)."""
    if not platform:
        return "The machine it ran on is not on record."
    variables = "".join(f"; {name}={value}" for name, value in sorted(platform["kernel_variables"].items()))
    return (f"Ran on {platform['cpu']} ({platform['torch_cpu_capability']}), torch {platform['torch']}, "
            f"numpy {platform['numpy']}{variables}.")


def cache_salt(checkpoint: str | Path | None) -> str:
    """What else decides a job's result: the checkpoint's bytes, crossway's code (the installed
    version and the sources of ``RESULT_PACKAGES``) and the numeric platform (``numeric_platform``),
    so a run resumed after the code changed, or on another machine, runs its jobs again instead of
    mixing results of two versions."""
    global _code_digest
    from importlib import import_module
    from importlib.metadata import PackageNotFoundError, version

    try:
        installed = version("crossway")
    except PackageNotFoundError:
        installed = "unknown"
    if _code_digest is None:
        _code_digest = source_digest([Path(import_module(name).__file__).parent for name in RESULT_PACKAGES])
    platform = json.dumps(numeric_platform(), sort_keys=True)
    return f"crossway {installed}, code {_code_digest[:16]}; checkpoint {file_digest(checkpoint)}; {platform}"


def _save(path: Path, result) -> None:
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    temporary.write_bytes(pickle.dumps(result))
    os.replace(temporary, path)  # atomic: a kill leaves the old state or the whole result


def run_parallel(function: Callable, jobs: Sequence[tuple], total: int, workers: int, label: str,
                 cache_dir: Path | None = None, salt: str = "", sizes: Sequence[int] | None = None) -> list:
    """``function(*job, progress)`` for every job in ``workers`` spawned processes.

    Each job puts the number of episodes it finished on ``progress``; this process prints
    ``label: done/total episodes, elapsed, ETA`` on stderr: a bar redrawn at most twice a second
    on a terminal, a line every 30 s (and at the end) into a log file. Results come back in job
    order.

    ``cache_dir``: keep each result there as it comes (``job_key``) and take the ones an earlier,
    stopped run left instead of running those jobs again; ``sizes``: episodes per job, so that the
    progress line counts the ones taken from the cache as done.
    """
    results: list = [None] * len(jobs)
    todo = list(range(len(jobs)))
    paths: list[Path | None] = [None] * len(jobs)
    done = 0
    if cache_dir is not None:
        cache_dir.mkdir(parents=True, exist_ok=True)
        todo = []
        for index, job in enumerate(jobs):
            paths[index] = cache_dir / f"{job_key(function, job, salt)}.pkl"
            try:
                results[index] = pickle.loads(paths[index].read_bytes())
                done += sizes[index] if sizes is not None else 0
            except FileNotFoundError:
                todo.append(index)
            except Exception as error:  # unreadable: run the job again rather than stop
                print(f"{label}: ignored a kept result that does not read ({type(error).__name__}: {error}); "
                      "running its job again", file=sys.stderr, flush=True)
                todo.append(index)
        if len(todo) < len(jobs):
            print(f"{label}: {len(jobs) - len(todo)} of {len(jobs)} jobs already done by an earlier run of this "
                  f"command (kept in {cache_dir}; delete it to start over); running the other {len(todo)}",
                  file=sys.stderr, flush=True)
        if not todo:
            return results
    interactive = sys.stderr.isatty()
    interval = 0.5 if interactive else 30.0
    prefix = "\r" if interactive else ""
    started = time.monotonic()
    done_at_start = done
    context = multiprocessing.get_context("spawn")  # workers start clean (Zenoh, torch threads)
    progress = context.Queue()
    # Ctrl-C raises KeyboardInterrupt, SIGTERM SystemExit(143): either unwinds the pool's context,
    # which terminates its workers
    stop = StopRequest(sigterm_exits=True)

    def keep(index: int):
        def callback(result) -> None:  # the pool's result thread, as each job returns
            results[index] = result
            if paths[index] is not None:
                try:
                    _save(paths[index], result)
                except OSError as error:  # a full disk must not stop the run: it only loses the keeping
                    print(f"{label}: could not keep a finished job in {cache_dir} ({error})", file=sys.stderr,
                          flush=True)
        return callback

    try:
        with stop_handlers(stop), context.Pool(processes=max(1, min(workers, len(todo))), initializer=_start_worker,
                          initargs=(progress, os.getpid())) as pool:
            pending = [pool.apply_async(_run_job, (function, jobs[index]), callback=keep(index)) for index in todo]
            shown = -1.0
            while not all(p.ready() for p in pending) or done < total:
                stop.check()
                try:
                    done += progress.get(timeout=0.5)
                except queue.Empty:
                    if all(p.ready() for p in pending):
                        break  # every job has returned and reported
                    continue
                elapsed = time.monotonic() - started
                if elapsed - shown < interval and done < total:
                    continue
                shown = elapsed
                filled = int(BAR_WIDTH * done / max(total, 1))
                bar = "#" * filled + "-" * (BAR_WIDTH - filled)
                rate = (done - done_at_start) / max(elapsed, 1e-9)
                eta = f"{(total - done) / rate:5.0f} s" if rate > 0 else "    ?"
                print(f"{prefix}{label} [{bar}] {done}/{total} episodes, {elapsed:5.0f} s, "
                      f"ETA {eta}", end="" if interactive else "\n",
                      file=sys.stderr, flush=True)
            for p in pending:
                p.get()  # a job's exception surfaces here
    finally:
        progress.close()
    if interactive:
        print(file=sys.stderr)
    return results
