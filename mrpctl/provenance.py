"""Where numbers come from: the versions of the packages that a saved run's or a campaign's numbers depend on."""

from __future__ import annotations

import platform
from importlib.metadata import PackageNotFoundError, version

__all__ = ["mrpctl_version", "versions"]


def versions() -> dict[str, str]:
    """The versions of the packages a campaign's numbers depend on."""
    found = {"python": platform.python_version()}
    for package in ("mrpctl", "numpy", "casadi", "xarray", "zarr", "dask"):
        try:
            found[package] = version(package)
        except PackageNotFoundError:  # pragma: no cover - a source tree without installation
            found[package] = "unknown"
    return found


def mrpctl_version() -> str:
    """The installed mrpctl's version (``0.0.0+unknown`` from a source tree that was never installed)."""
    try:
        return version("mrpctl")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "0.0.0+unknown"
