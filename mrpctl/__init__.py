"""mrpctl: delayed-feedback attitude control with MRP shadow-set switching."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from mrpctl import errors, model, mrp, paper
from mrpctl.errors import MrpctlError
from mrpctl.model import PlantModel, plant_model
from mrpctl.spacecraft import Spacecraft

try:
    __version__ = version("mrpctl")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = [
    "MrpctlError",
    "PlantModel",
    "Spacecraft",
    "__version__",
    "errors",
    "model",
    "mrp",
    "paper",
    "plant_model",
]
