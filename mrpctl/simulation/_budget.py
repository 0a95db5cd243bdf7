"""The sample-count and memory rules of a run and a batch: refuse up front what would not fit."""

from __future__ import annotations

import math
from typing import Any

from mrpctl._validation import available_memory, integer, positive_scalar
from mrpctl.engines.lanes import DEFAULT_WIDTH
from mrpctl.engines.scalar import STATE_BLOCK, slice_samples
from mrpctl.engines.stats import STATS_SIZE
from mrpctl.errors import SpecificationError
from mrpctl.flight import (
    NOISE_SIZE,
    DelayKind,
    DelayModel,
)
from mrpctl.model import INPUT_SIZE, STATE_SIZE

#: At most this many switch instants are kept per run when ``keep_every != 1`` (16 MB);
#: the count, the first and the last switch stay exact.
SWITCH_LIMIT = 2**20


# Bytes per kept sample in a result: m_k and u_k as computed (72), t (8), omega (24).
_BYTES_PER_KEPT = 104


_BYTES_PER_SWITCH = 16  # index and time


# Flight and predictor runs: the records (at most 15 numbers: the predictor's measurement, prediction and command)
# and the delay used per kept sample as computed (128) and their copies (128).
_BYTES_PER_RECORD = 256


#: simulate_batch's Python objects of each run before it runs (its delay in samples, its history row, references):
#: 276 B measured by tracemalloc (a second audit), rounded up
_BYTES_PER_RUN = 400


#: One run's SimulationResult in a trajectory batch beyond its kept samples (metrics, small arrays, the object):
#: 4.6-5.3 KB measured (RSS of 2e5 and 4e5 runs, keep_every None and 1), rounded up
_BYTES_PER_RESULT = 6000


#: The most samples one run integrates: about 28 h of one core at the compiled engine's 10^7 samples a second
#: (the CLI's sweep has the same limit); beyond it a run is refused up front instead of running for days (or
#: for ever: t_final * rate beyond 2^63 has no sample count).
MAX_RUN_SAMPLES = 1.0e12


def sample_horizon(t_final: Any, rate: float) -> tuple[float, int]:
    t_final = positive_scalar("t_final", t_final)
    total = t_final * rate
    if not total + 1 <= MAX_RUN_SAMPLES:
        raise SpecificationError(
            f"t_final: t_final * rate = {total:.3g} samples, more than one run integrates (limit "
            f"{MAX_RUN_SAMPLES:.0e} samples, about {MAX_RUN_SAMPLES / 1e7 / 3600:.0f} h of one core); "
            "choose a shorter t_final or a lower rate"
        )
    n = math.floor(total + 1e-9) + 1
    return t_final, n


def check_keep_every(keep_every: Any) -> int | None:
    if keep_every is None:
        return None
    return integer("keep_every", keep_every, minimum=1)


def memory_limit_bytes(memory_limit: Any) -> float:
    if memory_limit is not None:
        return positive_scalar("memory_limit", memory_limit)
    available = available_memory()
    return available / 2 if available else math.inf


def run_bytes(n: int, keep_every: int | None, *, switches: bool = True, flight: bool = False) -> int:
    """Bytes a result of n samples holds: the kept samples (with ``flight``, their records) and
    (at most) its switch instants."""
    kept = 0 if keep_every is None else (n - 1) // keep_every + 1
    switch_cap = (n if keep_every == 1 else min(n, SWITCH_LIMIT)) if switches else 0
    per_kept = _BYTES_PER_KEPT + (_BYTES_PER_RECORD if flight else 0)
    return kept * per_kept + switch_cap * _BYTES_PER_SWITCH


def workspace_bytes(n: int, d: int, substeps: int, width: int = 1) -> int:
    """Bytes of one worker's buffers: the d-sample ring (``width`` states per entry: 2 for the
    predictor's measurement and model copy) and the slice's switch flags."""
    return (min(d, n) + 1) * width * STATE_SIZE * 8 + min(slice_samples(substeps), n) * 8


def batch_run_bytes(n: int, keep_every: int | None, trajectories: bool, *, records: bool) -> int:
    """Bytes of each run of a simulate_batch call: its objects and statistics, and with ``trajectories`` its
    result (the kept samples, with ``records`` the flight records)."""
    size = _BYTES_PER_RUN + STATS_SIZE * 8 * 4
    if trajectories:
        size += _BYTES_PER_RESULT + run_bytes(n, keep_every, flight=records)
    return size


def kept_run_bytes(t_final: float, rate: float, keep_every: int | None = 1, *, records: bool = False) -> int:
    """Bytes [`simulate_batch`][mrpctl.simulate_batch] counts, before it allocates anything, for each run of a batch
    with ``trajectories=True`` of ``t_final`` s at ``rate`` Hz keeping every ``keep_every``-th sample (``records``:
    a flight, predictor or tracking run, whose result also keeps its records): what a caller that runs many such
    runs in groups sizes its groups by."""
    _, n = sample_horizon(t_final, rate)
    return batch_run_bytes(n, check_keep_every(keep_every), True, records=records)


def jitter_bytes(delay: DelayModel | None, d: int) -> int:
    """Bytes of the driver's arrival ring of a seeded jitter (d_max + 1 slots and 3 numbers, whatever n is)."""
    return (d + 4) * 8 if delay is not None and delay.kind is DelayKind.JITTER else 0


def check_memory(estimate: float, limit: float, *, t_final: float, keep_every: int | None, runs: int = 1) -> None:
    if estimate <= limit:
        return
    what = (
        f"{runs} runs (their kept samples, delay buffers and results)"
        if runs > 1
        else "the kept samples and the delay's buffers"
    )
    keeping = "metrics only" if keep_every is None else f"keep_every = {keep_every}"
    raise SpecificationError(
        f"t_final = {t_final:g} s with {keeping} needs about {estimate / 1e9:.3g} GB for {what}, "
        f"more than the limit of {limit / 1e9:.3g} GB (memory_limit; default half the available memory): "
        "keep fewer samples (keep_every=k keeps every k-th, keep_every=None only the metrics and switch instants), "
        "shorten t_final or tau (the ring holds tau * rate measurements), "
        + ("give fewer runs per call (a campaign, mrpctl.campaign, runs any number in chunks), " if runs > 1 else "")
        + "or raise memory_limit"
    )


def lane_bytes(runs: int, d: int, workers: int) -> int:
    """Bytes of the lane engine's buffers: every run's packed inputs and state (the inputs
    with a full inertia: x, memory, stats twice, K, parameters, J, J⁻¹) and, per worker,
    one batch of W lanes with its d + 1-sample ring and its d-sample history."""

    per_run = 2 * STATE_BLOCK + INPUT_SIZE * STATE_SIZE + 1 + 18
    per_batch = DEFAULT_WIDTH * (2 * STATE_BLOCK + INPUT_SIZE * STATE_SIZE + 1 + 18 + STATE_SIZE * (2 * d + 2))
    return 8 * (runs * per_run + min(workers, runs) * per_batch)


def lane_stream_bytes(n: int, d: int, substeps: int, workers: int, *, noise: bool, jitter: bool) -> int:
    """Bytes of the per-lane streams per worker when the runs have their own sensors (the driver's block of
    64 noise rows of every lane and one lane's, the lanes' keys and scales) or their own delay models (the lanes'
    jitter state: keys, d_min, j* and the d + 1 arrival ring; for a given sequence the slice's (samples, W)
    schedule, its checks and the arrival arrays of one run)."""
    rows = min(slice_samples(substeps), n)
    size = (64 * NOISE_SIZE * (DEFAULT_WIDTH + 1) + 4 * DEFAULT_WIDTH) if noise else 0
    size += ((4 + d) * DEFAULT_WIDTH + 3 * DEFAULT_WIDTH * rows + 5 * (rows + d)) if jitter else 0
    return 8 * workers * size
