"""Run a campaign chunk by chunk, in this process or on Dask, into its Zarr store; resume after an interrupt."""

from __future__ import annotations

import hashlib
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
from mrpctl.campaign._task import chunk_on_worker, simulate_chunk
from mrpctl.campaign.integrity import writer_lock
from mrpctl.campaign.spec import CampaignSpec
from mrpctl.campaign.store import CampaignStore
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


def _dask(
    spec: CampaignSpec, store: CampaignStore, todo: list[int], scheduler: str, workers: int | None
) -> Iterator[tuple[int, Any]]:
    if not todo:  # nothing to run: no connection to the cluster
        return
    # one attempt per call: a resumed campaign never receives a result the cluster kept from an earlier call
    token, attempt = campaign_token(spec, store.out), secrets.token_hex(4)
    # deferred: Dask, only for a Dask campaign or a store read lazily
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler == "local":
        # deferred: Dask, only for a Dask campaign or a store read lazily
        import dask

        # The cluster's own housekeeping competes with the workers for the same cores: no statistical
        # profiler (a stack sample every 10 ms in each worker), event-loop and system monitors at 1 s
        # rather than 20 ms / 500 ms, no memory monitor (a chunk's memory is bounded by the chunk).
        with dask.config.set(LOCAL_CLUSTER_CONFIG):
            cluster = LocalCluster(
                n_workers=workers or _cpus(),
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                memory_limit=0,
            )
        client = Client(cluster, set_as_default=False)
    else:
        try:
            client = Client(scheduler, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise _Lost(f"could not be reached ({type(exc).__name__})") from None
    try:
        slots = 2 * max(1, len(client.scheduler_info().get("workers", {})) or 1)
        pending = iter(todo)

        def submit(index: int) -> Any:  # the chunk's task: the spec's text and its files' numbers
            start, stop = store.bounds(index)
            task = (spec.source, spec.base.name, start, stop, spec.files)
            return client.submit(chunk_on_worker, *task, key=task_key(token, attempt, index), pure=False)

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
        client.close()
        if cluster is not None:
            cluster.close()


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
    source = _local(spec, store, todo, threads) if scheduler is None else _dask(spec, store, todo, scheduler, workers)
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
