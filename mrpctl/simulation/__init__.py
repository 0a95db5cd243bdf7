"""The sampled nonlinear closed loop with delayed feedback and shadow-set switching.

[`simulate`][mrpctl.simulation.simulate] runs one case, [`simulate_batch`][mrpctl.simulate_batch] many on a thread pool;
both
return frozen results (`mrpctl.simulation.results`). The closed loop's CasADi
Functions are built by [`mrpctl.loop`][mrpctl.loop] and run by the engines of `mrpctl.engines` (the
scalar engine with its C horizon driver, the lanes, or CasADi's virtual machine without a C
compiler). The model and the engine: ``design/switching.md``.
"""

from __future__ import annotations

from mrpctl.engines.stats import DIVERGENCE_BOUND, HISTORY_KINDS, SETTLING_ATTITUDE_DEG, SETTLING_OMEGA, SETTLING_SIGMA
from mrpctl.loop import MAX_SUBSTEPS, ClosedLoopFunctions, closed_loop_functions, delay_samples
from mrpctl.simulation._batch import simulate_batch
from mrpctl.simulation._budget import SWITCH_LIMIT, kept_run_bytes
from mrpctl.simulation._simulate import settling_tolerances, simulate
from mrpctl.simulation.results import BatchResult, SimulationResult

__all__ = [
    "DIVERGENCE_BOUND",
    "HISTORY_KINDS",
    "MAX_SUBSTEPS",
    "SETTLING_ATTITUDE_DEG",
    "SETTLING_OMEGA",
    "SETTLING_SIGMA",
    "SWITCH_LIMIT",
    "BatchResult",
    "ClosedLoopFunctions",
    "SimulationResult",
    "closed_loop_functions",
    "delay_samples",
    "kept_run_bytes",
    "settling_tolerances",
    "simulate",
    "simulate_batch",
]
