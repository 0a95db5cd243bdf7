"""A campaign on a Dask cluster started as an operator starts one, against the same campaign in this process.

The cluster is ``dask scheduler`` and ``workers`` ``dask worker ADDRESS --nthreads 1`` processes (the
commands of this environment, each its own program and process group) on loopback, as
``docs/how-to/cluster.md`` says; the campaign reaches it through ``run_campaign(spec, out,
scheduler="tcp://127.0.0.1:PORT")``, which is what ``mrpctl campaign run --scheduler`` calls. The campaign is
``examples/campaigns/tumble_fixed_inertia.toml`` (10 s at 1 kHz, ``count`` runs, chunk ``BENCH_CHUNK``).

Measured, interleaved (in-process, cluster, in-process, cluster, ...):

* ``cluster start``: from the first ``Popen`` until the scheduler lists every worker;
* round 0, ``cold``: the cluster's first campaign. The workers are fresh processes; by default they have
  an empty compile cache of their own (``BENCH_WORKER_CACHE=shared`` to give them this process's), so
  their first chunk imports mrpctl and compiles the engine, as on a node that never ran mrpctl;
* rounds 1.., ``warm``: the same cluster again (an operator's cluster after its first campaign);
* the cluster's programs are in this process's session (``BENCH_SESSIONS=own``: a session each, as from
  separate terminals; with the kernel's autogroup scheduling each session then gets its own share of a
  loaded machine, and the cluster more CPU than the in-process run);
* ``fresh worker``: after the rounds, the workers are restarted (new processes, engine in the cache)
  and each runs an 8-run chunk: the import and the engine load a replaced worker pays.

Every store is checked bit for bit (each variable's bytes, and ``xarray.Dataset.identical``) against the
first in-process store. The CPU seconds of all processes (this one, the scheduler, the nannies and the
workers) are summed for each campaign. The cluster is shut down on every exit (an exception, Ctrl-C,
SIGTERM): SIGTERM to each process group, SIGKILL after 20 s, and the bench checks that no process of
those groups is left.

Run: ``.venv/bin/python bench/campaign_cluster.py [count] [rounds]`` (defaults 100000 runs, 2 warm rounds).
"""

from __future__ import annotations

import contextlib
import os
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


def _warm(source: dict[str, Any]) -> tuple[float, str]:
    """On a worker: import, rebuild the spec, load (or compile) the engine, run 8 runs."""
    start = time.perf_counter()
    simulate_chunk(parse_campaign(source, name="bench"), 0, 8, threads=1)
    return time.perf_counter() - start, mrpctl.__file__


class Cluster:
    """``dask scheduler`` and ``workers`` single-threaded ``dask worker`` processes, each in its own session."""

    def __init__(self, folder: Path, workers: int, cache: Path | None, own_sessions: bool) -> None:
        self.address = f"tcp://127.0.0.1:{_port()}"
        self.log = open(folder / "cluster.log", "w")  # noqa: SIM115 (closed in stop)
        self.processes: list[subprocess.Popen[bytes]] = []
        env = dict(os.environ)
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


def _terminate(number: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + number)  # SIGTERM: unwind, so the finally shuts the cluster down


def main() -> None:
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    chunk = int(os.environ.get("BENCH_CHUNK", "2500"))
    workers = int(os.environ.get("BENCH_WORKERS", "2"))
    shared_cache = os.environ.get("BENCH_WORKER_CACHE", "empty") == "shared"
    own_sessions = os.environ.get("BENCH_SESSIONS", "one") == "own"
    if not DASK.exists():
        raise SystemExit(f"no dask command next to {sys.executable}")
    signal.signal(signal.SIGTERM, _terminate)
    signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C raises, even if started in the background
    spec = _spec(count)
    print(f"host: {cpu_model()}, {os.cpu_count()} CPUs; {vector_isa()}")
    print(
        f"campaign: {SPEC_FILE.name}, {count} runs of 10 s, chunk {chunk}; cluster: dask scheduler + {workers} "
        f"dask worker --nthreads 1 on loopback; in-process: {len(os.sched_getaffinity(0))} threads; "
        f"{rounds} warm rounds"
    )
    t = time.perf_counter()
    simulate_chunk(spec, 0, 8)  # compile or load the engine in this process (not timed with the runs)
    print(f"this process: engine ready in {time.perf_counter() - t:.2f} s; load {_load()}")

    work = Path(tempfile.mkdtemp(prefix="campaign_cluster_"))
    rows: list[tuple[str, int, float, float, str]] = []  # (path, round, wall, CPU, load before)
    cluster = None
    reference = None
    try:
        cache = None if shared_cache else work / "worker-cache"
        cluster = Cluster(work, workers, cache, own_sessions)
        autogroup = Path("/proc/sys/kernel/sched_autogroup_enabled")
        print(
            f"cluster start (Popen to {workers} workers listed) {cluster.started:.2f} s; worker cache: "
            f"{'this process' if shared_cache else 'empty, their own'}; cluster programs in "
            f"{'sessions of their own' if own_sessions else 'this session'} (autogroup scheduling "
            f"{autogroup.read_text().strip() if autogroup.exists() else 'absent'}); load {_load()}"
        )
        for r in range(rounds + 1):
            for path in ("in-process", "cluster"):
                out = work / f"{path}{r}"
                scheduler = cluster.address if path == "cluster" else None
                load = _load()
                tree = [psutil.Process(), *cluster.tree()]
                before = _cpu(tree)
                start = time.perf_counter()
                result = run_campaign(spec, out, chunk=chunk, scheduler=scheduler)
                wall = time.perf_counter() - start
                after = _cpu(tree)
                cpu = sum(after[pid] - before[pid] for pid in before if pid in after)
                assert result.complete and result.runs == count, result
                dataset = open_campaign(out)
                if reference is None:
                    reference = dataset
                else:
                    _same(reference, dataset, f"{path} round {r}")
                    shutil.rmtree(out)
                label = path if path == "in-process" else ("cluster, cold" if r == 0 else "cluster, warm")
                rows.append((label, r, wall, cpu, load))
                print(f"  round {r} {label}: {wall:.2f} s, {count / wall:.0f} runs/s, CPU {cpu:.1f} s, load {load}")
        # a replaced worker: a new process, the engine in the cache
        client = cluster.connect()
        client.restart()
        load = _load()
        fresh = client.gather(client.map(_warm, [spec.source] * workers, pure=False))
        paths = sorted({where for _, where in fresh})
        print(f"fresh worker processes: first 8-run chunk {', '.join(f'{t:.2f}' for t, _ in fresh)} s; load {load}")
        print(f"mrpctl on the workers: {', '.join(paths)}; here: {mrpctl.__file__}")
        assert paths == [mrpctl.__file__], paths
    finally:
        left = cluster.stop() if cluster is not None else []
        shutil.rmtree(work, ignore_errors=True)
        print(f"cluster shut down; processes left: {left or 'none'}")

    print("\n| round | path | wall (s) | runs/s | CPU s, all processes | load average (1, 5, 15 min) before |")
    print("|---|---|---|---|---|---|")
    for label, r, wall, cpu, load in rows:
        print(f"| {r} | {label} | {wall:.2f} | {count / wall:.0f} | {cpu:.1f} | {load} |")
    local = [wall for label, _, wall, _, _ in rows if label == "in-process"]
    remote = [wall for label, _, wall, _, _ in rows if label != "in-process"]
    cpu_local = [c for label, _, _, c, _ in rows if label == "in-process"]
    cpu_remote = [c for label, _, _, c, _ in rows if label != "in-process"]
    ratios = [b / a for a, b in zip(local, remote, strict=True)]
    warm = ratios[1:]
    print(f"\ncold (round 0) cluster / in-process wall: {ratios[0]:.3f}")
    if warm:
        print(
            f"warm cluster / in-process wall, rounds 1-{rounds}: min {min(warm):.3f}, median "
            f"{float(np.median(warm)):.3f}, max {max(warm):.3f}"
        )
        cpu_ratios = [b / a for a, b in zip(cpu_local[1:], cpu_remote[1:], strict=True)]
        print(
            f"warm cluster / in-process CPU s: min {min(cpu_ratios):.3f}, median {float(np.median(cpu_ratios)):.3f}, "
            f"max {max(cpu_ratios):.3f}"
        )
        print(f"cold campaign minus the median warm one: {remote[0] - float(np.median(remote[1:])):.2f} s")
    print(f"every cluster store equals the in-process store bit for bit: yes ({len(rows) - 1} compared)")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
