"""The campaign throughput figures in one run: each bench in a process of its own, one after the other, on this host.

1. ``campaign_dispersed.py``: a fully dispersed flown campaign (each run's own noise, jitter, inertia,
   disturbance, u_max, δ) against the same chunk with shared models (goal ≥ 0.7×);
2. ``predictor_lanes.py``: predictor campaigns on the lanes, both predictor forms, against the plain lanes
   (goal ≥ 0.5×);
3. ``lanes_rate.py``: the plain lanes against a hand-written SIMD loop compiled with the same IEEE flags (goal
   ≥ 0.85×);
4. ``campaign_cluster.py``: a campaign of ``CLUSTER_RUNS`` runs on a separately started ``dask scheduler`` and two
   ``dask worker`` processes against the same campaign in this process (goal: within 15 %; every store equal bit
   for bit).

Each bench measures its ratios against a reference run in its own process (interleaved rounds) and prints the
host's CPU and vector ISA; this script prints their whole output, then the tables again as a summary. The two
campaigns that share one cluster, each equal to its in-process run bit for bit with a worker killed, are a test
(``tests/test_campaign_cluster.py``), not a bench.

Run: ``.venv/bin/python bench/throughput.py [--quick]`` (``--quick``: fewer runs and rounds, 10⁴ cluster runs;
the default takes about 15 minutes on 2 cores).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: (script, arguments, quick arguments, how many of its last lines are its table)
BENCHES = (
    ("campaign_dispersed.py", ["64", "5"], ["32", "3"], 8),
    ("predictor_lanes.py", ["48", "5"], ["48", "3"], 13),
    ("lanes_rate.py", ["64", "3"], ["32", "2"], 14),
    ("campaign_cluster.py", ["100000", "2"], ["10000", "1"], 12),
)


def main() -> None:
    quick = "--quick" in sys.argv[1:]
    summaries = []
    for script, arguments, quick_arguments, tail in BENCHES:
        argv = [sys.executable, str(HERE / script), *(quick_arguments if quick else arguments)]
        print(f"=== {' '.join(argv[1:])} (load {os.getloadavg()[0]:.1f})", flush=True)
        start = time.perf_counter()
        done = subprocess.run(argv, capture_output=True, text=True, check=False)
        print(done.stdout, end="", flush=True)
        if done.returncode != 0:
            print(done.stderr, end="", file=sys.stderr)
        lines = done.stdout.rstrip("\n").split("\n")
        status = "ok" if done.returncode == 0 else f"FAILED (exit {done.returncode})"
        summaries.append((script, status, time.perf_counter() - start, lines[-tail:]))
    print("\n=== summary")
    for script, status, seconds, lines in summaries:
        print(f"--- {script}: {status}, {seconds:.0f} s")
        print("\n".join(lines))
    if any(status != "ok" for _, status, _, _ in summaries):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
