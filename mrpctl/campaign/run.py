"""Run a campaign chunk by chunk, in this process or on Dask, into its Zarr store; resume after an interrupt."""

from __future__ import annotations

import hashlib
import importlib
import itertools
import json
import logging
import math
import os
import secrets
import time
from collections.abc import Callable, Iterator
from concurrent.futures import CancelledError
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl._validation import integer
from mrpctl.campaign._task import shipped_files, simulate_chunk
from mrpctl.campaign.integrity import writer_lock
from mrpctl.campaign.spec import CampaignSpec
from mrpctl.campaign.store import STORE_NAME, CampaignStore
from mrpctl.errors import MrpctlError, SpecificationError

__all__ = ["CampaignProgress", "CampaignRun", "SchedulerLostError", "run_campaign", "simulate_chunk"]

logger = logging.getLogger(__name__)

#: Dask settings of the LocalCluster that ``scheduler="local"`` starts (bench/campaign_dask.py).
LOCAL_CLUSTER_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "1s",
}


class SchedulerLostError(MrpctlError):
    """The Dask scheduler could not be reached, or was lost mid-way; every chunk stored before stays in the store.

    Attributes
    ----------
    out : pathlib.Path
        The results folder (resumable: a second call runs only the chunks not stored).
    scheduler : str
        The scheduler's address.
    stored, todo : int
        Chunks this call stored before the loss; chunks it had to run.
    cause : str
        What happened ("was lost (CancelledError)", "could not be reached (OSError)").
    """

    def __init__(
        self, out: Path, scheduler: str, stored: int, todo: int, cause: str, resume: str | None = None
    ) -> None:
        self.out, self.scheduler, self.stored, self.todo, self.cause = out, scheduler, stored, todo, cause
        resume = resume or f"mrpctl campaign run CAMPAIGN.toml --out {out} (add --scheduler ADDRESS for a cluster)"
        super().__init__(
            f"the Dask scheduler {scheduler} {cause} after {stored} of {todo} chunk(s) were stored; "
            f"the store {out} keeps them: resume with {resume}"
        )


class _Lost(Exception):
    """Raised inside the Dask loop: the scheduler is gone (why, as a phrase)."""


@dataclass(frozen=True)
class CampaignProgress:
    """Where a running campaign stands, after a chunk is durably stored.

    Attributes
    ----------
    stored, count : int
        Runs in the store now (those of earlier calls included); runs in the campaign.
    simulated : int
        Runs this call simulated.
    diverged, not_settled : int
        Of the runs this call simulated: diverged; not settled by the end of the run (diverged included).
    elapsed : float
        Seconds since this call started simulating.
    """

    stored: int
    count: int
    simulated: int
    diverged: int
    not_settled: int
    elapsed: float

    @property
    def runs_per_second(self) -> float:
        """Runs simulated per second by this call (NaN before the first chunk)."""
        return self.simulated / self.elapsed if self.elapsed > 0 and self.simulated else math.nan

    @property
    def eta(self) -> float:
        """Seconds left at this call's rate (NaN before the first chunk)."""
        rate = self.runs_per_second
        return (self.count - self.stored) / rate if rate == rate and rate > 0 else math.nan

    def __str__(self) -> str:
        return (
            f"{self.stored}/{self.count} runs stored, {self.runs_per_second:.4g} runs/s, "
            f"{self.eta:.4g} s left; of {self.simulated} simulated: {self.diverged} diverged, "
            f"{self.not_settled} not settled"
        )


#: Called after each chunk is durably stored with where the campaign stands.
ProgressCallback = Callable[[CampaignProgress], None]

#: Called after each chunk is durably stored: (chunk index, first run, stop run).
ChunkCallback = Callable[[int, int, int], None]


def _cpus() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@dataclass(frozen=True)
class CampaignRun:
    """What [`run_campaign`][mrpctl.campaign.run_campaign] did.

    Attributes
    ----------
    out : pathlib.Path
        The results folder.
    chunks : int
        Chunks in the campaign.
    already_complete : int
        Chunks found complete in the store when the call started (resumed work).
    simulated : int
        Chunks simulated by this call.
    runs : int
        Runs simulated by this call.
    repaired : tuple of str
        The damaged chunks found when the call started (each with its runs and what was wrong), simulated again.
    verified : bool
        False for a store written without checksum records (its chunks could not be checked).
    """

    out: Path
    chunks: int
    already_complete: int
    simulated: int
    runs: int
    repaired: tuple[str, ...] = ()
    verified: bool = True

    @property
    def complete(self) -> bool:
        """True when every chunk of the campaign is stored."""
        return self.already_complete + self.simulated == self.chunks

    def __str__(self) -> str:
        resumed = f" (resumed: {self.already_complete} chunk(s) were already complete)" if self.already_complete else ""
        state = "complete" if self.complete else "INCOMPLETE"
        text = f"campaign {state}: {self.simulated} chunk(s), {self.runs} runs simulated into {self.out}{resumed}"
        if self.repaired:
            text += f"\n  re-ran {len(self.repaired)} damaged chunk(s): " + "; ".join(self.repaired)
        if not self.verified:
            text += (
                "\n  note: the store has no checksum records (an older mrpctl wrote it): its chunks were not verified"
            )
        return text


def campaign_token(spec: CampaignSpec, out: str | Path) -> str:
    """A short hash of the campaign (its file's values, its per-sample files) and of its store's path.

    Part of every Dask task key, so campaigns sharing one cluster never share a key (Dask would hand one
    chunk's result to both).
    """
    text = json.dumps(
        {
            "campaign": spec.source,
            "name": spec.base.name,
            "files": {key: each.sha256 for key, each in spec.files.items()},
            "out": str(Path(out).resolve()),
        },
        sort_keys=True,
        default=str,
    )
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def task_key(token: str, attempt: str, index: int) -> str:
    """The Dask key of chunk ``index``: ``chunk-<campaign token>-<attempt>-<index>`` (the index last)."""
    return f"chunk-{token}-{attempt}-{index}"


def _local(spec: CampaignSpec, store: CampaignStore, todo: list[int], threads: int | None) -> Iterator[tuple[int, Any]]:
    for index in todo:
        start, stop = store.bounds(index)
        yield index, simulate_chunk(spec, start, stop, threads=threads)


def _on_worker(function: str) -> Callable[..., Any]:
    """A Dask task's function that calls ``mrpctl.campaign._task.<function>`` on the worker.

    It is a closure, so Dask pickles it by value (its code and the name ``function``), not as a reference to a
    mrpctl module: the scheduler, which unpickles every task it is given, never imports mrpctl. (A reference
    made a cold scheduler import mrpctl on its event loop before it could hand out the first task, and only
    then did the workers start importing it.) The worker imports mrpctl in the task's thread, on the first call.
    Its keyword ``files`` is `shipped_files`'s data (plain, for the same reason).
    """

    def call(*args: Any, files: Any = None) -> Any:
        # on the worker, when the task runs (importlib itself is pickled by reference: standard library)
        task = importlib.import_module("mrpctl.campaign._task")
        return getattr(task, function)(*args, task.received_files(files))

    call.__name__ = function  # the Dask dashboard's name of the task's function
    return call


class _Session:
    """A campaign's Dask connection: its Client (and the ``LocalCluster`` of ``scheduler="local"``).

    `start` connects and sends each worker a warm-up task
    ([`warm_up_worker`][mrpctl.campaign._task.warm_up_worker], through `_on_worker`); `_run_locked` starts a
    session before it creates a new store, so that a fresh worker's import of mrpctl and its engine compile run
    while this process writes the store's template, not after it. A scheduler that cannot be reached is remembered and
    raised (as `_Lost`) when the chunks are submitted, after the store exists, as without a warm-up.
    """

    def __init__(self, spec: CampaignSpec, out: str | Path, scheduler: str, workers: int | None) -> None:
        self.spec, self.scheduler, self.workers = spec, scheduler, workers
        # one attempt per call: a resumed campaign never receives a result the cluster kept from an earlier call
        self.token, self.attempt = campaign_token(spec, out), secrets.token_hex(4)
        self.client: Any = None
        self.cluster: Any = None
        self.lost: str | None = None
        self.warm_ups: list[Any] = []  # held until the session closes; never waited for (a chunk raises errors)

    def start(self) -> None:
        """Connect (or start the local cluster) and send each worker listed now its warm-up task."""
        if self.client is not None or self.lost is not None:
            return
        # deferred: Dask, only for a Dask campaign or a store read lazily
        from dask.distributed import Client, LocalCluster

        if self.scheduler == "local":
            # deferred: Dask, only for a Dask campaign or a store read lazily
            import dask

            # The cluster's own housekeeping competes with the workers for the same cores: no statistical
            # profiler (a stack sample every 10 ms in each worker), event-loop and system monitors at 1 s
            # rather than 20 ms / 500 ms, no memory monitor (a chunk's memory is bounded by the chunk).
            with dask.config.set(LOCAL_CLUSTER_CONFIG):
                self.cluster = LocalCluster(
                    n_workers=self.workers or _cpus(),
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    memory_limit=0,
                )
            self.client = Client(self.cluster, set_as_default=False)
        else:
            try:
                self.client = Client(self.scheduler, set_as_default=False)
            except (OSError, TimeoutError) as exc:
                self.lost = f"could not be reached ({type(exc).__name__})"
                return
        spec, warm_up = self.spec, _on_worker("warm_up_worker")
        for i, worker in enumerate(sorted(self.client.scheduler_info().get("workers", {}))):
            self.warm_ups.append(
                self.client.submit(
                    warm_up,
                    spec.source,
                    spec.base.name,
                    files=shipped_files(spec.files),
                    key=f"warm-up-{self.token}-{self.attempt}-{i}",
                    workers=[worker],
                    allow_other_workers=False,
                    pure=False,
                )
            )

    def close(self) -> None:
        self.warm_ups.clear()
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None


def _dask(session: _Session, store: CampaignStore, todo: list[int]) -> Iterator[tuple[int, Any]]:
    if not todo:  # nothing to run: no connection to the cluster
        return
    # deferred: Dask, only for a Dask campaign or a store read lazily
    from dask.distributed import as_completed

    spec, token, attempt = session.spec, session.token, session.attempt
    session.start()  # a no-op if started before the store was created
    if session.lost is not None:
        raise _Lost(session.lost)
    client, chunk_task, files = session.client, _on_worker("chunk_on_worker"), shipped_files(spec.files)
    try:
        slots = 2 * max(1, len(client.scheduler_info().get("workers", {})) or 1)
        pending = iter(todo)

        def submit(index: int) -> Any:  # the chunk's task: the spec's text and its files' numbers
            start, stop = store.bounds(index)
            task = (spec.source, spec.base.name, start, stop)
            return client.submit(chunk_task, *task, files=files, key=task_key(token, attempt, index), pure=False)

        # the client is not the process's default (set_as_default=False: a campaign leaves the caller's Dask
        # scheduler as it was), so as_completed is given its event loop
        first = [submit(index) for index in itertools.islice(pending, slots)]
        futures = as_completed(first, loop=client.loop)
        del first
        for future in futures:
            try:
                values = future.result()
            except (CancelledError, OSError, TimeoutError) as exc:
                if future.status == "error":  # the task's own error: raised as it is
                    raise
                raise _Lost(f"was lost ({type(exc).__name__})") from None
            yield int(str(future.key).rsplit("-", 1)[1]), values
            del future
            following = next(pending, None)
            if following is not None:
                futures.add(submit(following))
    finally:
        session.close()


def run_campaign(
    spec: CampaignSpec,
    out: str | Path,
    *,
    chunk: int | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    threads: int | None = None,
    on_chunk: ChunkCallback | None = None,
    on_progress: ProgressCallback | None = None,
) -> CampaignRun:
    """Run (or resume) a campaign into ``out/campaign.zarr``.

    Chunks already complete in the store are skipped; the others (including one that was
    half-written when an earlier call was interrupted) are simulated and written as they
    finish. The stored values do not depend on the chunk size, the order, interruptions
    or where the chunks ran.

    Parameters
    ----------
    spec : CampaignSpec
        The campaign.
    out : path
        Results folder.
    chunk : int, optional
        Runs per chunk for a new store (default 1000); a resumed store keeps its own.
    scheduler : str, optional
        None: run in this process (a thread pool over the compiled engine). ``"local"``:
        a Dask ``LocalCluster`` of ``workers`` single-threaded processes (it spawns them: a
        script that calls this must do so under ``if __name__ == "__main__":``, as for any
        process pool; the CLI does). ``"tcp://host:port"``:
        the Dask scheduler at that address (its workers need mrpctl and a C compiler, or
        use CasADi's virtual machine).
    workers : int, optional
        Processes of the local Dask cluster (default: the CPUs available).
    threads : int, optional
        Threads of the in-process runner (default: the CPUs available).
    on_chunk : callable, optional
        ``on_chunk(index, start, stop)`` after each chunk is stored (progress bars; an
        exception raised there stops the campaign, which resumes later).
    on_progress : callable, optional
        ``on_progress(CampaignProgress)`` after each chunk is stored: runs stored, runs/s, time left,
        and the failures (diverged, not settled) so far.

    Returns
    -------
    CampaignRun

    Raises
    ------
    StoreLockedError
        If another process is writing the same store: the one-writer lock
        ([writer_lock][mrpctl.campaign.integrity.writer_lock]) is held from before the store is created
        until this call returns or raises (Ctrl-C included).
    StoreDamagedError
        If a file written at the store's creation is damaged (a damaged *chunk* is simulated again).
    """
    if "://" in str(out):
        raise SpecificationError(
            f"out: {out} is a URL; the store is a folder of this machine (only this process writes it, the "
            "workers send their chunks back), so give a local or mounted path"
        )
    if chunk is not None:
        chunk = integer("chunk", chunk, minimum=1)
    if workers is not None:
        workers = integer("workers", workers, minimum=1)
    if scheduler is not None and scheduler != "local" and "://" not in scheduler:
        raise SpecificationError(f"scheduler must be 'local' or an address such as tcp://host:8786, got {scheduler!r}")
    with writer_lock(out):
        return _run_locked(spec, out, chunk, scheduler, workers, threads, on_chunk, on_progress)


def _run_locked(
    spec: CampaignSpec,
    out: str | Path,
    chunk: int | None,
    scheduler: str | None,
    workers: int | None,
    threads: int | None,
    on_chunk: ChunkCallback | None,
    on_progress: ProgressCallback | None = None,
) -> CampaignRun:
    session = None if scheduler is None else _Session(spec, out, scheduler, workers)
    try:
        if session is not None and not (Path(out) / STORE_NAME).exists():
            session.start()  # a new store: the workers warm up while this process writes its template
        return _run_chunks(spec, out, chunk, scheduler, threads, on_chunk, on_progress, session)
    finally:
        if session is not None:
            session.close()


def _run_chunks(
    spec: CampaignSpec,
    out: str | Path,
    chunk: int | None,
    scheduler: str | None,
    threads: int | None,
    on_chunk: ChunkCallback | None,
    on_progress: ProgressCallback | None,
    session: _Session | None,
) -> CampaignRun:
    store = CampaignStore(out, spec, chunk)
    complete = store.complete()
    repaired = tuple(str(d) for d in store.damaged)
    for damage in store.damaged:
        logger.warning("campaign %s: re-running damaged %s", spec.base.name, damage)
    todo = [int(i) for i in np.flatnonzero(~complete)]
    already = int(complete.sum())
    logger.info("campaign %s: %d of %d chunks to run", spec.base.name, len(todo), store.chunks)
    runs = simulated = diverged = not_settled = 0
    stored = sum(store.bounds(i)[1] - store.bounds(i)[0] for i in range(store.chunks) if complete[i])
    started = time.monotonic()
    source = _local(spec, store, todo, threads) if session is None else _dask(session, store, todo)
    try:
        for index, values in source:
            store.write(index, values)
            start, stop = store.bounds(index)
            simulated += 1
            runs += stop - start
            stored += stop - start
            diverged += int(np.count_nonzero(values["diverged"]))
            not_settled += int(np.count_nonzero(~np.asarray(values["converged"], dtype=bool)))
            if on_chunk is not None:
                on_chunk(index, start, stop)
            if on_progress is not None:
                on_progress(
                    CampaignProgress(stored, spec.count, runs, diverged, not_settled, time.monotonic() - started)
                )
    except _Lost as lost:
        raise SchedulerLostError(Path(out), str(scheduler), simulated, len(todo), str(lost)) from None
    finally:
        close = getattr(source, "close", None)
        if close is not None:
            close()
    return CampaignRun(
        out=Path(out),
        chunks=store.chunks,
        already_complete=already,
        simulated=simulated,
        runs=runs,
        repaired=repaired,
        verified=store.verified,
    )
