"""Where the Dask path of a campaign loses time against the in-process path; prints one table.

The campaign is ``examples/campaigns/tumble_fixed_inertia.toml`` (SO(3) attitudes, rates up to
0.3 rad/s, gain scale 0.8-1.2, DelayAware, 10 s at 1 kHz) with ``count`` runs. Measured in this
process, back to back and interleaved over ``rounds`` rounds (the machine is shared: read the
ratios):

* ``in-process``: ``run_campaign(spec, out, chunk=C)`` (a thread pool over the lane engine);
* ``dask``: ``run_campaign(..., scheduler=<address>)`` on one ``LocalCluster`` of 2 single-threaded
  worker processes started once (its start and the workers' first compile are timed apart);
* the parts: sampling (``run_inputs``), simulation (``simulate_runs``) on 1 and on 2 threads, the
  client's Zarr write of one chunk, and a round trip of an empty task;
* chunk-size variants of the Dask path.

Every Dask store is checked bit for bit against the in-process one.

Run: ``.venv/bin/python bench/campaign_dask.py [count] [rounds]`` (defaults 20000 runs, 2 rounds).
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl.campaign import open_campaign, parse_campaign, run_campaign, run_inputs

try:
    from mrpctl.campaign._task import simulate_chunk
except ImportError:  # a tree before the chunk task had its own module (to bench the old code)
    from mrpctl.campaign.run import simulate_chunk
from mrpctl.campaign.store import CampaignStore

ROOT = Path(__file__).resolve().parent.parent
SPEC_FILE = ROOT / "examples" / "campaigns" / "tumble_fixed_inertia.toml"


def _spec(count: int) -> Any:
    with SPEC_FILE.open("rb") as handle:
        data = tomllib.load(handle)
    data["count"] = count
    return parse_campaign(data, name="bench")


def _timed(function: Any, *args: Any, **kwargs: Any) -> tuple[float, Any]:
    start = time.perf_counter()
    value = function(*args, **kwargs)
    return time.perf_counter() - start, value


def _noop() -> int:
    return 0


def _cpu(dask_worker: Any = None) -> float:
    """CPU seconds (user + system) of the calling process, all its threads."""
    import resource

    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _warm(source: dict[str, Any]) -> float:
    """On a worker: import, rebuild the spec, compile or load the engine (one tiny chunk)."""
    start = time.perf_counter()
    simulate_chunk(parse_campaign(source, name="bench"), 0, 8, threads=1)
    return time.perf_counter() - start


def main() -> None:
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    chunks = [int(c) for c in os.environ.get("BENCH_CHUNKS", "1000,5000").split(",")]
    spec = _spec(count)
    print(f"campaign: {count} runs of 10 s, rounds {rounds}, chunks {chunks}, load {os.getloadavg()[0]:.2f}")
    simulate_chunk(spec, 0, 8)  # compile or load the engine in this process
    from dask.distributed import Client, LocalCluster

    t_cluster, cluster = _timed(LocalCluster, n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    t_warm = client.gather(client.map(_warm, [spec.source] * 2, pure=False))
    t_noop, _ = _timed(lambda: client.gather([client.submit(_noop, pure=False) for _ in range(20)]))
    print(
        f"cluster start {t_cluster:.2f} s; first chunk per worker (import + engine) {max(t_warm):.2f} s; "
        f"20 empty tasks {t_noop * 1e3:.0f} ms"
    )
    address = cluster.scheduler_address

    times: dict[str, list[float]] = {}
    work = Path(tempfile.mkdtemp(prefix="campaign_dask_"))
    reference = None
    try:
        for r in range(rounds):
            for chunk in chunks:
                # the parts of one chunk
                t, _ = _timed(run_inputs, spec, 0, chunk)
                times.setdefault(f"sample {chunk}", []).append(t)
                t, values = _timed(simulate_chunk, spec, 0, chunk, threads=1)
                times.setdefault(f"chunk 1 thread {chunk}", []).append(t)
                t, values = _timed(simulate_chunk, spec, 0, chunk, threads=2)
                times.setdefault(f"chunk 2 threads {chunk}", []).append(t)
                store = CampaignStore(work / f"w{r}_{chunk}", spec, chunk)
                t, _ = _timed(store.write, 0, values)
                times.setdefault(f"write {chunk}", []).append(t)
                for label, scheduler in (("in-process", None), ("dask", address)):
                    out = work / f"{label}{r}_{chunk}"
                    before, here = client.run(_cpu), _cpu()
                    t, _ = _timed(run_campaign, spec, out, chunk=chunk, scheduler=scheduler)
                    after = client.run(_cpu)
                    times.setdefault(f"{label} {chunk}", []).append(t)
                    cpu = _cpu() - here + sum(after[w] - before[w] for w in before)
                    times.setdefault(f"{label} {chunk} CPU (all processes)", []).append(cpu)
                    dataset = open_campaign(out)
                    if reference is None:
                        reference = dataset
                    else:
                        for name in reference.data_vars:
                            assert reference[name].values.tobytes() == dataset[name].values.tobytes(), (label, name)
                    shutil.rmtree(out)
    finally:
        client.close()
        cluster.close()
        shutil.rmtree(work, ignore_errors=True)
    print("\n| measure | best (s) | all (s) | runs/s |")
    print("|---|---|---|---|")
    for name, values in times.items():
        n = int(name.split(" ")[-1]) if not name.startswith(("in-process", "dask")) else count
        print(f"| {name} | {min(values):.3f} | {', '.join(f'{v:.2f}' for v in values)} | {n / min(values):.0f} |")
    for chunk in chunks:
        a, b = min(times[f"in-process {chunk}"]), min(times[f"dask {chunk}"])
        ca, cb = min(times[f"in-process {chunk} CPU (all processes)"]), min(times[f"dask {chunk} CPU (all processes)"])
        print(f"chunk {chunk}: CPU seconds dask / in-process = {cb / ca:.3f} (best of {rounds})")
        print(
            f"chunk {chunk}: wall dask / in-process = {b / a:.3f} (best of {rounds}); "
            "per round "
            + ", ".join(
                f"{y / x:.3f}" for x, y in zip(times[f"in-process {chunk}"], times[f"dask {chunk}"], strict=True)
            )
        )
    print("stores identical bit for bit: yes")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
