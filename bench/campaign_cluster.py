"""A campaign on a Dask cluster started as an operator starts one, against the same campaign in this process.

The cluster is ``dask scheduler`` and ``workers`` ``dask worker ADDRESS --nthreads 1`` processes (the
commands of this environment, each its own program and process group) on loopback, as
``docs/how-to/cluster.md`` says; the campaign reaches it through ``run_campaign(spec, out,
scheduler="tcp://127.0.0.1:PORT")``, which is what ``mrpctl campaign run --scheduler`` calls (``BENCH_CLI=1``:
each campaign, in-process and cluster alike, is ``mrpctl campaign run ... --chunk C [--scheduler ADDRESS]`` as
a process of its own). The campaign is ``examples/campaigns/tumble_fixed_inertia.toml`` (10 s at 1 kHz,
``count`` runs, chunk ``BENCH_CHUNK``, default 2500).

Measured, interleaved (in-process, cluster, in-process, cluster, ...):

* ``cluster start``: from the first ``Popen`` until the scheduler lists every worker;
* ``first chunk stored after``: from the ``run_campaign`` call until its first chunk is in the store (the
  store's creation, and on a cold cluster the imports and the compile before the first chunk can run);
* round 0, ``cold``: the cluster's first campaign. The workers are fresh processes; by default they have
  an empty compile cache of their own (``BENCH_WORKER_CACHE=shared`` to give them this process's), so
  their first chunk imports mrpctl and compiles the engine, as on a node that never ran mrpctl;
* rounds 1.., ``warm``: the same cluster again (an operator's cluster after its first campaign);
* the cluster's programs are in this process's session (``BENCH_SESSIONS=own``: a session each, as from
  separate terminals; with the kernel's autogroup scheduling each session then gets its own share of a
  loaded machine, and the cluster more CPU than the in-process run);
* ``BENCH_QUIET=1``: the scheduler and workers get the Dask settings of the ``LocalCluster`` that
  ``scheduler="local"`` starts (``LOCAL_CLUSTER_CONFIG`` as ``DASK_...`` variables, ``--memory-limit 0``);
* ``first compile``: after the rounds, the workers' cache is emptied and the workers restarted (new
  processes); each runs an 8-run chunk: the import and the compile of a node that never ran mrpctl (the two
  workers of this host share the cache: one compiles, the other waits for it and loads it);
* ``fresh worker``: restarted again (new processes, engine in the cache), each runs an 8-run chunk: the
  import and the engine load a replaced worker pays.

Every store is checked bit for bit (each variable's bytes, and ``xarray.Dataset.identical``) against the
first in-process store. The CPU seconds are counted apart for the campaign's process (this one, or the
command line's) and for the cluster's (scheduler, nannies, workers; idle during the in-process runs); the
CPU ratio is the cluster path's whole (its campaign process and the cluster) over the in-process run's own.
The cluster is shut down on every exit (an exception, Ctrl-C, SIGTERM): SIGTERM to each process group,
SIGKILL after 20 s, and the bench checks that no process of those groups is left; if the bench itself is
killed (SIGKILL), the kernel sends each program SIGTERM (``PR_SET_PDEATHSIG``).

Run: ``.venv/bin/python bench/campaign_cluster.py [count] [rounds]`` (defaults 100000 runs, 2 warm rounds).
"""

from __future__ import annotations

import contextlib
import os
import re
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np
import psutil
import xarray as xr
from _host import cpu_model, vector_isa

import mrpctl
from mrpctl.campaign import open_campaign, parse_campaign, run_campaign
from mrpctl.campaign._task import simulate_chunk
from mrpctl.campaign.run import LOCAL_CLUSTER_CONFIG

ROOT = Path(__file__).resolve().parent.parent
SPEC_FILE = ROOT / "examples" / "campaigns" / "tumble_fixed_inertia.toml"
DASK = Path(sys.executable).with_name("dask")


def _spec(count: int) -> Any:
    with SPEC_FILE.open("rb") as handle:
        data = tomllib.load(handle)
    data["count"] = count
    return parse_campaign(data, name="bench")


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _warm(source: dict[str, Any]) -> tuple[float, float, str]:
    """On a worker: import mrpctl's chunk task, then rebuild the spec, load (or compile) the engine and run 8 runs.

    The imports are in the body (this function travels by value), so the first is timed here."""
    start = time.perf_counter()
    import mrpctl
    from mrpctl.campaign import parse_campaign
    from mrpctl.campaign._task import simulate_chunk

    imported = time.perf_counter()
    simulate_chunk(parse_campaign(source, name="bench"), 0, 8, threads=1)
    return imported - start, time.perf_counter() - imported, mrpctl.__file__


def _first_chunks(client: Any, source: dict[str, Any], workers: int, what: str) -> list[str]:
    """An 8-run chunk on each of the (restarted) workers; prints the import, the engine and the end-to-end times."""
    load = _load()
    start = time.perf_counter()
    done = client.gather([client.submit(_warm, source, pure=False, workers=[w]) for w in _names(client)])
    total = time.perf_counter() - start
    print(
        f"{what}: import {', '.join(f'{i:.2f}' for i, _, _ in done)} s, then spec + engine + 8 runs "
        f"{', '.join(f'{e:.2f}' for _, e, _ in done)} s; {total:.2f} s from submit to both results; load {load}"
    )
    assert len(done) == workers, done
    return sorted({where for _, _, where in done})


def _names(client: Any) -> list[str]:
    return sorted(client.scheduler_info()["workers"])


class Cluster:
    """``dask scheduler`` and ``workers`` single-threaded ``dask worker`` processes, each in its own session."""

    def __init__(self, folder: Path, workers: int, cache: Path | None, own_sessions: bool, quiet: bool = False) -> None:
        self.address = f"tcp://127.0.0.1:{_port()}"
        self.log = open(folder / "cluster.log", "w")  # noqa: SIM115 (closed in stop)
        self.processes: list[subprocess.Popen[bytes]] = []
        env = dict(os.environ)
        if quiet:  # the settings of the LocalCluster that scheduler="local" starts, as the programs' environment
            env.update({_variable(key): str(value) for key, value in LOCAL_CLUSTER_CONFIG.items()})
        if cache is not None:
            env["MRPCTL_CACHE_DIR"] = str(cache)
        # Each program its own process group (stopped as a group). In this session by default: with the kernel's
        # autogroup scheduling (/proc/sys/kernel/sched_autogroup_enabled) every session gets an equal share of a
        # loaded machine, so programs in sessions of their own would get more CPU than the in-process run.
        place = {"start_new_session": True} if own_sessions else {"process_group": 0}
        common: dict[str, Any] = {
            "stdout": self.log,
            "stderr": subprocess.STDOUT,
            "preexec_fn": _die_with_parent,
            **place,
        }
        port = self.address.rsplit(":", 1)[1]
        start = time.perf_counter()
        self.processes.append(
            subprocess.Popen(
                [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", port, "--dashboard-address", ":0"],
                env=env,
                **common,
            )
        )
        for i in range(workers):
            command = [str(DASK), "worker", self.address, "--nthreads", "1", "--name", f"w{i}"]
            command += ["--memory-limit", "0"] if quiet else []
            self.processes.append(subprocess.Popen(command, env=env, **common))
        from dask.distributed import Client

        deadline = time.monotonic() + 120
        self.client: Any = None
        while self.client is None:
            self._alive()
            try:
                self.client = Client(self.address, timeout="2s", set_as_default=False)
            except OSError:
                time.sleep(0.1)
            if time.monotonic() > deadline:
                raise RuntimeError("the scheduler did not start within 120 s (see cluster.log)")
        self.client.wait_for_workers(workers, timeout=120)
        self.started = time.perf_counter() - start
        self.client.close()  # no client of the bench's own on the cluster while a campaign is timed
        self.client = None

    def connect(self) -> Any:
        from dask.distributed import Client

        self.client = Client(self.address, timeout="10s", set_as_default=False)
        return self.client

    def _alive(self) -> None:
        for process in self.processes:
            if process.poll() is not None:
                raise RuntimeError(f"{process.args[1]} exited with {process.returncode} (see cluster.log)")

    def tree(self) -> list[psutil.Process]:
        """The cluster's processes: scheduler, nannies and their worker processes."""
        found = []
        for process in self.processes:
            try:
                top = psutil.Process(process.pid)
                found += [top, *top.children(recursive=True)]
            except psutil.NoSuchProcess:
                pass
        return found

    def stop(self) -> list[int]:
        """Close the client, SIGTERM each process group, SIGKILL after 20 s; the pids left (none expected)."""
        if self.client is not None:
            self.client.close()
        groups = [process.pid for process in self.processes]  # each leads its own group: pid == process group
        for group in groups:
            _signal_group(group, signal.SIGTERM)
        deadline = time.monotonic() + 20
        for process in self.processes:
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(timeout=max(0.1, deadline - time.monotonic()))
        for group in groups:
            _signal_group(group, signal.SIGKILL)  # whatever did not exit, the nannies' children included
        for process in self.processes:
            process.wait(timeout=30)
        self.log.close()
        deadline = time.monotonic() + 10  # the groups' helpers (multiprocessing's resource trackers) exit last
        while _members(groups) and time.monotonic() < deadline:
            time.sleep(0.2)
        for group in groups:
            _signal_group(group, signal.SIGKILL)
        time.sleep(0.5)
        return _members(groups)


def _members(groups: list[int]) -> list[int]:
    return [p.pid for p in psutil.process_iter(["pid"]) if _group(p.pid) in groups]


def _variable(key: str) -> str:
    """Dask's environment variable of a configuration key: ``a.b-c.d`` -> ``DASK_A__B_C__D``."""
    return "DASK_" + key.upper().replace(".", "__").replace("-", "_")


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when this bench dies, even by SIGKILL (Linux; elsewhere the finally only)."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def _signal_group(group: int, number: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(group, number)


def _group(pid: int) -> int | None:
    try:
        return os.getpgid(pid)
    except (ProcessLookupError, PermissionError):
        return None


def _cpu(processes: list[psutil.Process]) -> dict[int, float]:
    seconds = {}
    for process in processes:
        try:
            times = process.cpu_times()
            seconds[process.pid] = times.user + times.system
        except psutil.NoSuchProcess:
            pass
    return seconds


def _same(reference: xr.Dataset, dataset: xr.Dataset, label: str) -> None:
    assert set(reference.data_vars) == set(dataset.data_vars), label
    for name in [*reference.data_vars, *reference.coords]:
        a, b = reference[name].values, dataset[name].values
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), (label, name)
    assert reference.identical(dataset), label


def _cli(spec_file: Path, out: Path, chunk: int, scheduler: str | None, log: Path) -> None:
    """``mrpctl campaign run SPEC --out OUT --chunk C [--scheduler ADDRESS]`` as its own process."""
    command = [sys.executable, "-m", "mrpctl", "campaign", "run", str(spec_file), "--out", str(out)]
    command += ["--chunk", str(chunk), *(["--scheduler", scheduler] if scheduler else [])]
    with log.open("a") as handle:
        subprocess.run(command, stdout=handle, stderr=subprocess.STDOUT, check=True)


def _spent(before: dict[int, float], after: dict[int, float]) -> float:
    return sum(after[pid] - before[pid] for pid in before if pid in after)


def _terminate(number: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + number)  # SIGTERM: unwind, so the finally shuts the cluster down


def main() -> None:
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    chunk = int(os.environ.get("BENCH_CHUNK", "2500"))
    workers = int(os.environ.get("BENCH_WORKERS", "2"))
    shared_cache = os.environ.get("BENCH_WORKER_CACHE", "empty") == "shared"
    own_sessions = os.environ.get("BENCH_SESSIONS", "one") == "own"
    quiet = os.environ.get("BENCH_QUIET", "0") == "1"
    cli = os.environ.get("BENCH_CLI", "0") == "1"
    if not DASK.exists():
        raise SystemExit(f"no dask command next to {sys.executable}")
    signal.signal(signal.SIGTERM, _terminate)
    signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C raises, even if started in the background
    spec = _spec(count)
    print(f"host: {cpu_model()}, {os.cpu_count()} CPUs; {vector_isa()}")
    print(
        f"campaign: {SPEC_FILE.name}, {count} runs of 10 s, chunk {chunk}; cluster: dask scheduler + {workers} "
        f"dask worker --nthreads 1 on loopback; in-process: {len(os.sched_getaffinity(0))} threads; "
        f"{rounds} warm rounds; each campaign by "
        f"{'mrpctl campaign run, a process of its own' if cli else 'run_campaign in this process'}"
    )
    t = time.perf_counter()
    simulate_chunk(spec, 0, 8)  # compile or load the engine in this process (not timed with the runs)
    print(f"this process: engine ready in {time.perf_counter() - t:.2f} s; load {_load()}")

    work = Path(tempfile.mkdtemp(prefix="campaign_cluster_"))
    spec_file = SPEC_FILE
    if cli and count != tomllib.loads(SPEC_FILE.read_text())["count"]:
        spec_file = work / SPEC_FILE.name
        text = re.sub(r"(?m)^count = .*$", f"count = {count}", SPEC_FILE.read_text())
        spec_file.write_text(text)
    rows: list[tuple[str, int, float, float, float, str]] = []  # path, round, wall, CPU driver, CPU cluster, load
    cluster = None
    reference = None
    try:
        cache = None if shared_cache else work / "worker-cache"
        cluster = Cluster(work, workers, cache, own_sessions, quiet)
        autogroup = Path("/proc/sys/kernel/sched_autogroup_enabled")
        print(
            f"cluster start (Popen to {workers} workers listed) {cluster.started:.2f} s; worker cache: "
            f"{'this process' if shared_cache else 'empty, their own'}; cluster programs in "
            f"{'sessions of their own' if own_sessions else 'this session'}; Dask settings "
            f"{'of scheduler=local (BENCH_QUIET=1)' if quiet else 'the defaults'} (autogroup scheduling "
            f"{autogroup.read_text().strip() if autogroup.exists() else 'absent'}); load {_load()}"
        )
        for r in range(rounds + 1):
            for path in ("in-process", "cluster"):
                out = work / f"{path}{r}"
                scheduler = cluster.address if path == "cluster" else None
                load = _load()
                here, tree = [psutil.Process()], cluster.tree()
                before, before_cluster = _cpu(here), _cpu(tree)
                children = resource.getrusage(resource.RUSAGE_CHILDREN)
                start = time.perf_counter()
                if cli:
                    _cli(spec_file, out, chunk, scheduler, work / "cli.log")
                else:
                    stored: list[float] = []  # when the first chunk was stored (s from the call)

                    def first(index: int, a: int, b: int, stored: list[float] = stored, start: float = start) -> None:
                        if not stored:
                            stored.append(time.perf_counter() - start)

                    result = run_campaign(spec, out, chunk=chunk, scheduler=scheduler, on_chunk=first)
                    assert result.complete and result.runs == count, result
                wall = time.perf_counter() - start
                ended = resource.getrusage(resource.RUSAGE_CHILDREN)  # the command line's process, once waited for
                driver = _spent(before, _cpu(here)) + ended.ru_utime + ended.ru_stime
                driver -= children.ru_utime + children.ru_stime
                on_cluster = _spent(before_cluster, _cpu(tree))
                dataset = open_campaign(out)
                if reference is None:
                    reference = dataset
                else:
                    _same(reference, dataset, f"{path} round {r}")
                    shutil.rmtree(out)
                label = path if path == "in-process" else ("cluster, cold" if r == 0 else "cluster, warm")
                rows.append((label, r, wall, driver, on_cluster, load))
                first_chunk = f", first chunk stored after {stored[0]:.2f} s" if not cli and stored else ""
                print(
                    f"  round {r} {label}: {wall:.2f} s, {count / wall:.0f} runs/s, CPU s: campaign's process "
                    f"{driver:.1f}, cluster {on_cluster:.1f}{first_chunk}; load {load}",
                    flush=True,
                )
        client = cluster.connect()
        if cache is not None:  # the workers' first compile: new processes, their cache emptied
            shutil.rmtree(cache)
            client.restart()
            _first_chunks(client, spec.source, workers, "first compile (fresh workers, empty cache)")
        client.restart()  # a replaced worker: a new process, the engine in the cache
        paths = _first_chunks(client, spec.source, workers, "fresh workers, engine in the cache")
        print(f"mrpctl on the workers: {', '.join(paths)}; here: {mrpctl.__file__}")
        assert paths == [mrpctl.__file__], paths
    finally:
        left = cluster.stop() if cluster is not None else []
        shutil.rmtree(work, ignore_errors=True)
        print(f"cluster shut down; processes left: {left or 'none'}")

    print(
        "\n| round | path | wall (s) | runs/s | CPU s, the campaign's process | CPU s, cluster processes "
        "| load average (1, 5, 15 min) before |"
    )
    print("|---|---|---|---|---|---|---|")
    for label, r, wall, driver, on_cluster, load in rows:
        idle = " (idle)" if label == "in-process" else ""
        print(f"| {r} | {label} | {wall:.2f} | {count / wall:.0f} | {driver:.1f} | {on_cluster:.1f}{idle} | {load} |")
    local = [row for row in rows if row[0] == "in-process"]
    remote = [row for row in rows if row[0] != "in-process"]
    ratios = [b[2] / a[2] for a, b in zip(local, remote, strict=True)]
    # CPU: everything the cluster path spent (its driver, scheduler, nannies, workers) over the in-process run's own
    cpu_ratios = [(b[3] + b[4]) / a[3] for a, b in zip(local, remote, strict=True)]
    print(f"\ncold (round 0) cluster / in-process: wall {ratios[0]:.3f}, CPU s {cpu_ratios[0]:.3f}")
    if rounds:
        for what, values in (("wall", ratios[1:]), ("CPU s", cpu_ratios[1:])):
            print(
                f"warm cluster / in-process {what}, rounds 1-{rounds}: min {min(values):.3f}, "
                f"median {float(np.median(values)):.3f}, max {max(values):.3f}"
            )
        idle = [a[4] / a[2] for a in local]
        print(f"the idle cluster during the in-process runs: {min(idle):.3f}-{max(idle):.3f} cores")
    print(f"every cluster store equals the in-process store bit for bit: yes ({len(rows) - 1} compared)")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
