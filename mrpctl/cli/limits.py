"""What one command may ask for: the memory a run, a delay history or a sweep would keep, and the time a
sweep would take, refused before the work starts."""

from __future__ import annotations

import os
from collections.abc import Sequence

from mrpctl.errors import SpecificationError
from mrpctl.scenario import Scenario

__all__ = [
    "BYTES_PER_DELAY_SAMPLE",
    "BYTES_PER_SAMPLE",
    "BYTES_PER_SWEEP_RUN",
    "MAX_SWEEP_SAMPLES",
    "SAMPLES_PER_SECOND",
    "check_history_fits",
    "check_run_fits",
    "check_sweep_fits",
    "format_size",
    "memory_limit",
]


#: Bytes a run keeps per recorded sample: t, σ, ω, u, the switch flag and the engine's output buffers.
BYTES_PER_SAMPLE = 112


#: Bytes per delayed sample (the d-sample history block and the ring buffer, 6 doubles each).
BYTES_PER_DELAY_SAMPLE = 96


#: Bytes a sweep keeps per run (its row of the table, its initial state and the batch metrics).
BYTES_PER_SWEEP_RUN = 1024


#: Measured throughput of the compiled engine on one core (samples/s; 60 001 samples in 6.2 ms).
SAMPLES_PER_SECOND = 1.0e7


#: Largest number of samples a sweep integrates (about 28 h on one core at SAMPLES_PER_SECOND).
MAX_SWEEP_SAMPLES = 1.0e12


def memory_limit() -> float:
    """Half of the machine's physical memory (bytes): the most one command may ask for."""
    try:
        return 0.5 * os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, OSError, ValueError):  # pragma: no cover - not POSIX
        return 4.0 * 2**30


def format_size(nbytes: float) -> str:
    for unit, scale in (("TB", 2**40), ("GB", 2**30), ("MB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes / 2**10:.3g} KB"


def check_run_fits(scenario: Scenario) -> None:
    """Refuse, before starting, a run whose kept trajectory and history would not fit in memory."""
    samples = scenario.t_final * scenario.rate + 1.0
    delayed = scenario.tau * scenario.rate + 1.0
    need = BYTES_PER_SAMPLE * samples + BYTES_PER_DELAY_SAMPLE * delayed
    limit = memory_limit()
    if need > limit:
        raise SpecificationError(
            f"t_final = {scenario.t_final:g} s, tau = {scenario.tau:g} s at rate = {scenario.rate:g} Hz would keep "
            f"{samples:.3g} samples and {delayed:.3g} delayed samples, about {format_size(need)}, more than the "
            f"{format_size(limit)} allowed (half of this machine's memory); choose a shorter --t-final or a lower rate"
        )


def check_history_fits(scenario: Scenario) -> None:
    """Refuse a delay of more samples than the d-sample history block can hold in memory."""
    delayed = scenario.tau * scenario.rate + 1.0
    need = BYTES_PER_DELAY_SAMPLE * delayed
    limit = memory_limit()
    if need > limit:
        raise SpecificationError(
            f"tau = {scenario.tau:g} s at rate = {scenario.rate:g} Hz is {delayed:.3g} delayed samples, about "
            f"{format_size(need)}, more than the {format_size(limit)} allowed (half of this machine's memory); "
            "choose a lower rate"
        )


def check_sweep_fits(base: Scenario, count: int, taus: Sequence[float], chunk: int) -> None:
    """Refuse, before starting, a sweep that would not fit in memory or would not end within about a day.

    Kept: one table row per run, and the d-sample histories of the ``chunk`` runs of one batch call.
    """
    samples = base.t_final * base.rate + 1.0
    delayed = max(taus) * base.rate + 1.0
    need = BYTES_PER_SWEEP_RUN * count + BYTES_PER_DELAY_SAMPLE * delayed * min(chunk, count)
    limit = memory_limit()
    if need > limit:
        raise SpecificationError(
            f"{count} runs with delays up to {max(taus):g} s at {base.rate:g} Hz would keep about {format_size(need)}, "
            f"more than the {format_size(limit)} allowed (half of this machine's memory); choose a smaller --count "
            "(split the sweep with --seed) or shorter delays"
        )
    total = samples * count
    if total > MAX_SWEEP_SAMPLES:
        raise SpecificationError(
            f"{count} runs of t_final = {base.t_final:g} s at {base.rate:g} Hz are {total:.3g} samples, about "
            f"{total / SAMPLES_PER_SECOND / 3600:.3g} h on one core (limit {MAX_SWEEP_SAMPLES:.0e} samples); "
            "choose a shorter --t-final or a smaller --count"
        )
