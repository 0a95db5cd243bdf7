"""Monte Carlo campaigns: dispersed runs from (seed, run index), stored in Zarr chunk by chunk, on Dask.

>>> from mrpctl.campaign import load_campaign, run_campaign, open_campaign   # doctest: +SKIP
>>> spec = load_campaign("examples/campaigns/tumble.toml")                    # doctest: +SKIP
>>> run_campaign(spec, "results/tumble")                                     # doctest: +SKIP
>>> open_campaign("results/tumble")                                          # doctest: +SKIP

See ``design/campaigns.md`` for the sampling, the store layout and resuming, ``design/campaigns-cluster.md`` for
clusters.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mrpctl.campaign.report import CampaignReport, ReplayResult, replay, report, write_report
    from mrpctl.campaign.run import CampaignRun, run_campaign, simulate_chunk
    from mrpctl.campaign.sampling import RunInputs, run_inputs
    from mrpctl.campaign.spec import CampaignSpec, load_campaign, parse_campaign
    from mrpctl.campaign.store import open_campaign

# Imported on first use (PEP 562), so that a Dask worker unpickling the chunk task
# (mrpctl.campaign._task) does not import xarray, zarr and matplotlib it never uses.
_WHERE = {
    "CampaignReport": "report",
    "ReplayResult": "report",
    "replay": "report",
    "report": "report",
    "write_report": "report",
    "CampaignRun": "run",
    "run_campaign": "run",
    "simulate_chunk": "_task",
    "RunInputs": "sampling",
    "run_inputs": "sampling",
    "CampaignSpec": "spec",
    "load_campaign": "spec",
    "parse_campaign": "spec",
    "open_campaign": "store",
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'mrpctl.campaign' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"mrpctl.campaign.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])


class _Package(types.ModuleType):
    """Keeps ``mrpctl.campaign.report`` the function (as an eager ``from ... import report`` did):
    importing the submodule ``report`` must not replace the lazily bound function by the module."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "report" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


__all__ = [
    "CampaignReport",
    "CampaignRun",
    "CampaignSpec",
    "ReplayResult",
    "RunInputs",
    "load_campaign",
    "open_campaign",
    "parse_campaign",
    "replay",
    "report",
    "run_campaign",
    "run_inputs",
    "simulate_chunk",
    "write_report",
]
