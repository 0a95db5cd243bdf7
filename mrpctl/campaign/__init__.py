"""Monte Carlo campaigns: dispersed runs from (seed, run index), stored in Zarr chunk by chunk, on Dask.

>>> from mrpctl.campaign import load_campaign, run_campaign, open_campaign   # doctest: +SKIP
>>> spec = load_campaign("examples/campaigns/tumble.toml")                    # doctest: +SKIP
>>> run_campaign(spec, "results/tumble")                                     # doctest: +SKIP
>>> open_campaign("results/tumble")                                          # doctest: +SKIP

See ``design/campaigns.md`` for the sampling, the store layout, resuming and clusters.
"""

from __future__ import annotations

from mrpctl.campaign.report import CampaignReport, ReplayResult, replay, report, write_report
from mrpctl.campaign.run import CampaignRun, run_campaign, simulate_chunk
from mrpctl.campaign.sampling import RunInputs, run_inputs
from mrpctl.campaign.spec import CampaignSpec, load_campaign, parse_campaign
from mrpctl.campaign.store import open_campaign

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
