"""mrpctl: delayed-feedback attitude control with MRP shadow-set switching.

The flow: a :class:`Spacecraft` and gains K go to :mod:`mrpctl.design` (PD gains, LMI
certificates, the exact delay margin, synthesis), to :func:`simulate` and
:func:`simulate_batch` (:mod:`mrpctl.simulation`: the sampled nonlinear closed loop
with a switching rule, generated as C through CasADi from the Functions of
:mod:`mrpctl.loop`), to :mod:`mrpctl.plots` and to :mod:`mrpctl.export`. cvxpy is
imported on the first LMI solve and matplotlib only by :mod:`mrpctl.plots`.
"""

from __future__ import annotations

from mrpctl import design, errors, loop, model, mrp, paper, simulation
from mrpctl._export import ExportResult, export
from mrpctl.errors import (
    CodegenError,
    CompilerWarning,
    DimensionError,
    InertiaWarning,
    MrpctlError,
    SpecificationError,
)
from mrpctl.loop import ClosedLoopFunctions, closed_loop_functions
from mrpctl.model import PlantModel, plant_model
from mrpctl.predictor import OnPredicted, Predictor
from mrpctl.provenance import mrpctl_version
from mrpctl.scenario import Scenario, load_scenario
from mrpctl.simulation import BatchResult, SimulationResult, simulate, simulate_batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed, SwitchingRule

__version__ = mrpctl_version()

__all__ = [
    "BatchResult",
    "BoundaryLayer",
    "ClosedLoopFunctions",
    "CodegenError",
    "CompilerWarning",
    "DelayAware",
    "DimensionError",
    "ExportResult",
    "InertiaWarning",
    "MrpctlError",
    "NoSwitching",
    "OnCurrent",
    "OnDelayed",
    "OnPredicted",
    "PlantModel",
    "Predictor",
    "Scenario",
    "SimulationResult",
    "Spacecraft",
    "SpecificationError",
    "SwitchingRule",
    "__version__",
    "closed_loop_functions",
    "design",
    "errors",
    "export",
    "load_scenario",
    "loop",
    "model",
    "mrp",
    "paper",
    "plant_model",
    "simulate",
    "simulate_batch",
    "simulation",
]
