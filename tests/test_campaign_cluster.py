"""Campaigns on a Dask cluster started by someone else: `dask scheduler` and two `dask worker` processes on
loopback, as an operator would start them. Two campaigns share the cluster at once, a worker is killed with
SIGKILL mid-way, and each store equals its in-process run bit for bit; a lost scheduler ends with one line
that names the store and the command that resumes it."""

from __future__ import annotations

import copy
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from mrpctl.campaign import open_campaign, run_campaign
from mrpctl.campaign.run import SchedulerLostError
from mrpctl.campaign.spec import parse_campaign
from mrpctl.errors import SpecificationError

pytestmark = pytest.mark.xdist_group("cluster")

DASK = Path(sys.executable).with_name("dask")

SPEC = {
    "count": 16,
    "tau": 0.05,
    "rate": 100.0,
    "t_final": 3.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"k_sigma": -70.11, "k_omega": -163.08},
    "rule": {"type": "hysteretic", "delta": 0.1},
    "flight": {"attitude_noise": 1e-4, "rate_noise": 1e-5, "u_max": 50.0},
    "dispersions": {"attitude": {"angle_deg": [0.0, 180.0]}, "omega": {"magnitude": [0.0, 0.3]}},
}


def _spec(name: str, seed: int):
    return parse_campaign({**copy.deepcopy(SPEC), "name": name, "seed": seed})


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait(condition, what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.2)


class Cluster:
    """A scheduler and two workers, each its own program (the `dask` command of this environment)."""

    def __init__(self, folder: Path) -> None:
        if not DASK.exists():
            pytest.skip("the dask command is not installed next to this Python")
        self.address = f"tcp://127.0.0.1:{_port()}"
        env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False", "OMP_NUM_THREADS": "1"}
        log = open(folder / "cluster.log", "w")  # noqa: SIM115 (closed in stop)
        self.log = log
        port = self.address.rsplit(":", 1)[1]
        common = {"stdout": log, "stderr": subprocess.STDOUT, "env": env, "start_new_session": True}
        self.scheduler = subprocess.Popen(
            [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", port, "--dashboard-address", ":0"], **common
        )
        self.workers = [
            subprocess.Popen(
                [
                    str(DASK),
                    "worker",
                    self.address,
                    "--nthreads",
                    "1",
                    "--memory-limit",
                    "0",
                    "--name",
                    f"w{i}",
                    "--dashboard-address",
                    ":0",
                ],
                **common,
            )
            for i in range(2)
        ]
        from dask.distributed import Client

        _wait(lambda: self._workers(Client) == 2, "two workers")

    def _workers(self, client_class) -> int:
        try:
            with client_class(self.address, timeout="2s") as client:
                return len(client.scheduler_info()["workers"])
        except OSError:
            return 0

    def stop(self) -> None:
        for process in [*self.workers, self.scheduler]:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)
        self.log.close()


@pytest.fixture
def cluster(tmp_path):
    started = Cluster(tmp_path)
    try:
        yield started
    finally:
        started.stop()


def _identical(a: xr.Dataset, b: xr.Dataset) -> None:
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        assert a[name].values.tobytes() == b[name].values.tobytes(), name
    assert np.array_equal(a["run"].values, np.arange(a.sizes["run"]))  # every run stored once, in order


def test_two_campaigns_share_a_cluster_and_survive_a_killed_worker(cluster, tmp_path):
    specs = {"a": _spec("a", 1), "b": _spec("b", 2)}
    for name, spec in specs.items():
        assert run_campaign(spec, tmp_path / f"{name}-here", chunk=2, threads=1).complete
    killed = threading.Event()

    def kill_once(index: int, start: int, stop: int) -> None:
        if not killed.is_set():
            killed.set()
            os.killpg(cluster.workers[0].pid, signal.SIGKILL)  # mid-way: the other campaign's tasks are running

    results: dict[str, object] = {}

    def run(name: str) -> None:
        try:
            results[name] = run_campaign(
                specs[name],
                tmp_path / f"{name}-cluster",
                chunk=2,
                scheduler=cluster.address,
                on_chunk=kill_once if name == "a" else None,
            )
        except BaseException as exc:  # reported below
            results[name] = exc

    threads = [threading.Thread(target=run, args=(name,)) for name in specs]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=300)
    assert killed.is_set() and cluster.workers[0].poll() is not None, results  # the worker is dead
    for name in specs:
        result = results[name]
        assert not isinstance(result, BaseException), result
        assert result.complete and result.simulated == 8, result
        _identical(open_campaign(tmp_path / f"{name}-cluster"), open_campaign(tmp_path / f"{name}-here"))


def test_a_lost_scheduler_ends_with_one_line_naming_the_store_and_the_resume(cluster, tmp_path):
    spec = _spec("lost", 3)
    out = tmp_path / "lost"

    def kill_scheduler(index: int, start: int, stop: int) -> None:
        if cluster.scheduler.poll() is None:
            os.killpg(cluster.scheduler.pid, signal.SIGKILL)

    started = time.monotonic()
    with pytest.raises(SchedulerLostError) as lost:
        run_campaign(spec, out, chunk=2, scheduler=cluster.address, on_chunk=kill_scheduler)
    message = str(lost.value)
    assert "\n" not in message and cluster.address in message and str(out) in message
    assert f"resume with mrpctl campaign run CAMPAIGN.toml --out {out}" in message
    assert 1 <= lost.value.stored < 8 and lost.value.todo == 8
    assert time.monotonic() - started < 120
    # the store kept what was written: resuming here finishes it, equal to a run done here from the start
    resumed = run_campaign(spec, out, chunk=2, threads=1)
    assert resumed.complete and resumed.already_complete == lost.value.stored
    assert run_campaign(spec, tmp_path / "here", chunk=2, threads=1).complete
    _identical(open_campaign(out), open_campaign(tmp_path / "here"))


def test_an_unreachable_scheduler_is_one_line_on_the_command_line(tmp_path, capsys):
    import dask
    import distributed  # noqa: F401  its config defaults exist before the set below, which on exit removes what it added

    from mrpctl.cli import main

    spec_file = tmp_path / "c.toml"
    spec_file.write_text(
        'name = "u"\ncount = 4\nseed = 1\ntau = 0.05\nrate = 100.0\nt_final = 1.0\n'
        "[spacecraft]\ninertia = [140.0, 100.0, 80.0]\n[gains]\nk_sigma = -70.11\nk_omega = -163.08\n"
        '[rule]\ntype = "hysteretic"\ndelta = 0.1\n',
        encoding="utf-8",
    )
    address = f"tcp://127.0.0.1:{_port()}"  # nothing listens there
    with dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
        code = main(["campaign", "run", str(spec_file), "--out", str(tmp_path / "o"), "--scheduler", address])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("mrpctl: error:") and err.count("\n") == 1, err
    assert "could not be reached" in err and f"--out {tmp_path / 'o'} --scheduler {address}" in err


def test_an_object_store_url_for_the_store_is_refused():
    with pytest.raises(SpecificationError, match="out: s3://bucket/x is a URL"):
        run_campaign(_spec("url", 1), "s3://bucket/x")


def test_an_object_store_url_is_refused_on_the_command_line(tmp_path, capsys):
    from mrpctl.cli import main

    with pytest.raises(SystemExit) as stop:
        main(["campaign", "run", str(tmp_path / "c.toml"), "--out", "s3://bucket/x"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "s3://bucket/x is a URL" in err and err.count("\n") == 1, err


def _warm_up_states(client) -> list[str]:
    """The scheduler's states of the campaigns' warm-up tasks (one per worker)."""
    return client.run_on_scheduler(
        lambda dask_scheduler: sorted(ts.state for key, ts in dask_scheduler.tasks.items() if "warm-up-" in str(key))
    )


def test_a_fresh_cluster_warms_its_workers_while_the_store_is_created_and_its_scheduler_never_imports_mrpctl(
    cluster, tmp_path, monkeypatch
):
    """On a cluster that never ran mrpctl, each worker imports mrpctl and loads the engine (a warm-up task) while
    the caller writes the new store's template, and the scheduler hands out the tasks without importing mrpctl."""
    from dask.distributed import Client

    from mrpctl.campaign import store as store_module

    spec = _spec("cold", 4)
    original = store_module.CampaignStore._create
    seen: dict[str, object] = {}
    with Client(cluster.address, set_as_default=False) as watcher:

        def create(self) -> None:  # the store's template is written only once every warm-up has finished
            _wait(lambda: _warm_up_states(watcher) == ["memory", "memory"], "both warm-ups done", timeout=120)
            seen["workers"] = watcher.run(lambda: "mrpctl.campaign._task" in sys.modules)
            assert not (tmp_path / "cold" / "campaign.zarr").exists()
            original(self)

        monkeypatch.setattr(store_module.CampaignStore, "_create", create)
        result = run_campaign(spec, tmp_path / "cold", chunk=4, scheduler=cluster.address)
        on_scheduler = watcher.run_on_scheduler(lambda: sorted(m for m in sys.modules if m.split(".")[0] == "mrpctl"))
        assert _warm_up_states(watcher) == []  # released with the campaign's client
    assert result.complete and result.simulated == 4, result
    assert list(seen["workers"].values()) == [True, True], seen  # type: ignore[union-attr]
    assert on_scheduler == [], on_scheduler
    monkeypatch.undo()
    assert run_campaign(spec, tmp_path / "here", chunk=4, threads=1).complete
    _identical(open_campaign(tmp_path / "cold"), open_campaign(tmp_path / "here"))


def test_a_chunk_task_unpickles_where_mrpctl_cannot_be_imported(tmp_path):
    """What the scheduler unpickles of a chunk (Dask's own pickle): no mrpctl import; run where mrpctl is, the
    unpickled task gives the chunk the campaign computes here, the per-sample files' numbers included."""
    from distributed.protocol.pickle import dumps

    from mrpctl.campaign._task import shipped_files, simulate_chunk
    from mrpctl.campaign.run import _on_worker

    delays = tmp_path / "delays.csv"
    rows = int(3.0 * 100.0) + 1  # one delay per sample: 0.01 .. 0.05 s, whole periods of the 100 Hz loop
    np.savetxt(delays, (1 + (np.arange(rows) * 3) % 5) / 100.0, fmt="%.17g")
    data = {
        **copy.deepcopy(SPEC),
        "name": "pickled",
        "seed": 5,
        "flight": {**SPEC["flight"], "delay_file": str(delays)},
    }
    spec = parse_campaign(data)
    assert spec.files, "the campaign has a per-sample file"
    task = tmp_path / "task.pickle"
    task.write_bytes(
        dumps((_on_worker("chunk_on_worker"), spec.source, spec.base.name, 3, 9, shipped_files(spec.files)))
    )
    code = (
        "import pickle, sys; sys.modules['mrpctl'] = None; from distributed.protocol.pickle import loads; "
        f"task = loads(open({str(task)!r}, 'rb').read()); "
        "print(sorted(m for m in sys.modules if m.startswith('mrpctl.'))); del sys.modules['mrpctl']; "
        "function, *args, files = task; values = function(*args, files=files); "
        f"pickle.dump(values, open({str(tmp_path / 'values.pickle')!r}, 'wb'))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert done.stdout.strip() == "[]", done.stdout
    import pickle

    values = pickle.loads((tmp_path / "values.pickle").read_bytes())
    expected = simulate_chunk(spec, 3, 9)
    assert sorted(values) == sorted(expected)
    for name, array in expected.items():
        assert np.asarray(values[name]).tobytes() == np.asarray(array).tobytes(), name
