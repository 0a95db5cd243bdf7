"""mrpctl: delayed-feedback attitude control with MRP shadow-set switching.

The flow: a [`Spacecraft`][mrpctl.Spacecraft] and gains K go to [`mrpctl.design`][mrpctl.design] (PD gains, LMI
certificates, the exact delay margin, synthesis), to [`simulate`][mrpctl.simulation.simulate] and
[`simulate_batch`][mrpctl.simulate_batch] ([`mrpctl.simulation`][mrpctl.simulation]: the sampled nonlinear closed loop
with a switching rule, generated as C through CasADi from the Functions of
[`mrpctl.loop`][mrpctl.loop]), to [`mrpctl.plots`][mrpctl.plots] and to [`mrpctl.export`][mrpctl._export.export]. cvxpy
is
imported on the first LMI solve and matplotlib only by [`mrpctl.plots`][mrpctl.plots].
"""

from __future__ import annotations

from mrpctl import conventions, design, errors, loop, model, mrp, paper, simulation
from mrpctl._export import ExportResult, export, export_wheel_controller
from mrpctl.conventions import PDGains
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
from mrpctl.predictor import OnPredicted, Predictor, PredictorForm
from mrpctl.provenance import mrpctl_version
from mrpctl.scenario import Scenario, load_scenario
from mrpctl.simulation import BatchResult, SimulationResult, simulate, simulate_batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed, SwitchingRule
from mrpctl.wheels import WheelCluster

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
    "PDGains",
    "PlantModel",
    "Predictor",
    "PredictorForm",
    "Scenario",
    "SimulationResult",
    "Spacecraft",
    "SpecificationError",
    "SwitchingRule",
    "WheelCluster",
    "__version__",
    "closed_loop_functions",
    "conventions",
    "design",
    "errors",
    "export",
    "export_wheel_controller",
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
