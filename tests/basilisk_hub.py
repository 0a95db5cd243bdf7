"""The part every Basilisk cross-check sets up the same way: one process with one task at the control period
and a spacecraft hub of inertia J started at mrpctl's state x0 = [σ; ω/4] (imported only where Basilisk is)."""

from __future__ import annotations

from typing import Any

import numpy as np

from mrpctl.interop import basilisk_state


def simulation_and_hub(period: float, inertia: np.ndarray, x0: np.ndarray) -> tuple[Any, Any]:
    """(sim, body): a SimBaseClass with task "task" every ``period`` s, and a Spacecraft whose hub has inertia
    ``inertia`` (kg m², the whole spacecraft's) and starts at σ_BN, ω_BN_B of ``x0``."""
    from Basilisk.simulation import spacecraft  # type: ignore[import-untyped]
    from Basilisk.utilities import SimulationBaseClass, macros  # type: ignore[import-untyped]

    sigma0, omega0 = basilisk_state(x0)
    sim = SimulationBaseClass.SimBaseClass()
    sim.CreateNewProcess("process").addTask(sim.CreateNewTask("task", macros.sec2nano(period)))
    body = spacecraft.Spacecraft()
    body.ModelTag = "spacecraft"
    body.hub.IHubPntBc_B = np.asarray(inertia, dtype=float).tolist()
    body.hub.sigma_BNInit = sigma0.reshape(3, 1).tolist()
    body.hub.omega_BN_BInit = omega0.reshape(3, 1).tolist()
    return sim, body
