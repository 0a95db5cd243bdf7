"""`mrpctl campaign report --json` and the trajectories of the worst (and chosen) runs kept with the campaign."""

from __future__ import annotations

import copy
import hashlib
import json

import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl.campaign import run_campaign
from mrpctl.campaign.report import WORST_CRITERION, report
from mrpctl.campaign.spec import parse_campaign
from mrpctl.campaign.store import open_campaign
from mrpctl.cli import main
from mrpctl.data import load

SPEC = {
    "name": "kept",
    "count": 8,
    "seed": 4,
    "tau": 0.05,
    "rate": 100.0,
    "t_final": 2.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"k_sigma": -70.11, "k_omega": -163.08},
    "rule": {"type": "hysteretic", "delta": 0.1},
    "dispersions": {"attitude": {"angle_deg": [150.0, 180.0]}, "omega": {"magnitude": [0.0, 0.5]}},
}


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    out = tmp_path_factory.mktemp("kept")
    assert run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=4, threads=1).complete
    return out


def _severity(case) -> int:
    return {"diverged": 0, "not settled": 1, "slow": 2}[case["reason"]]


def test_report_json_is_strict_and_orders_the_worst_by_severity(store, capsys):
    assert main(["campaign", "report", str(store), "--json", "--worst", "8"]) == 0
    document = json.loads(capsys.readouterr().out)  # the whole stdout is one JSON document
    dataset = open_campaign(store)
    assert document["complete"] == 8 and document["converged"] == int(dataset["converged"].sum())
    assert document["worst_criterion"] == WORST_CRITERION
    worst = document["worst"]
    assert sorted(case["run"] for case in worst) == list(range(8))
    keys = [(_severity(c), -(c["settling_time"] if c["settling_time"] is not None else np.inf)) for c in worst]
    assert keys == sorted(keys)  # most severe first, then the slowest to settle
    # the interval is scipy.stats.binomtest's Wilson interval of the same counts
    from scipy.stats import binomtest

    ci = binomtest(document["converged"], 8).proportion_ci(method="wilson")
    assert document["wilson_95"] == [ci.low, ci.high]
    assert "Infinity" not in json.dumps(document) and "NaN" not in json.dumps(document)


def test_the_worst_runs_and_a_chosen_run_are_kept_checksummed_and_reload_as_the_campaign_ran(store, capsys):
    assert main(["campaign", "report", str(store), "--json", "--trajectories", "2", "--trajectory-run", "5"]) == 0
    document = json.loads(capsys.readouterr().out)
    kept = document["trajectories"]
    expected = [case.run for case in report(store, worst=2).worst] + [5]
    expected = list(dict.fromkeys(expected))
    assert [entry["run"] for entry in kept] == expected
    dataset = open_campaign(store)
    sums = dict(reversed(line.split("  ")) for line in (store / "trajectories" / "SHA256SUMS").read_text().splitlines())
    for entry in kept:
        path = store / "trajectories" / f"run-{entry['run']}.nc"
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        assert entry["sha256"] == digest == sums[path.name]
        result = load(path)
        row = dataset.sel(run=entry["run"])
        assert result.switch_count == int(row["switch_count"])
        stored = float(row["settling_time"])  # NaN in the store: not settled (None on a result)
        assert (result.settling_time is None and np.isnan(stored)) or result.settling_time == stored
        assert result.max_sigma == float(row["max_sigma"])
        assert np.array_equal(result.sigma[0], np.asarray(row["sigma0"]))


def test_the_table_names_the_criterion_and_the_files(store, capsys):
    assert main(["campaign", "report", str(store), "--trajectories", "1"]) == 0
    out = capsys.readouterr().out
    assert WORST_CRITERION in out and "1 trajectories (runs" in out and "SHA256SUMS" in out


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--trajectories", "-1"], "trajectories"),
        (["--trajectory-run", "8"], "run"),
        (["--trajectories", "9"], "trajectories: 9 worst runs asked"),
    ],
)
def test_bad_trajectory_requests_are_one_line(store, capsys, argv, needle):
    assert main(["campaign", "report", str(store), *argv]) == 2
    one_line_error(capsys, needle)


def test_progress_reports_runs_rate_and_failures_as_the_store_holds_them(tmp_path):
    from mrpctl.campaign.run import CampaignProgress

    states: list[CampaignProgress] = []
    spec = parse_campaign(copy.deepcopy(SPEC))
    result = run_campaign(spec, tmp_path / "p", chunk=3, threads=1, on_progress=states.append)
    assert result.complete and [s.stored for s in states] == [3, 6, 8]
    dataset = open_campaign(tmp_path / "p")
    last = states[-1]
    assert last.count == 8 and last.simulated == 8
    assert last.diverged == int(dataset["diverged"].sum())
    assert last.not_settled == int((~dataset["converged"].values.astype(bool)).sum())
    assert last.runs_per_second > 0 and last.eta == 0.0
    assert "8/8 runs stored" in str(last)
    # a resumed call counts the stored runs of before and simulates nothing
    again: list[CampaignProgress] = []
    assert run_campaign(spec, tmp_path / "p", on_progress=again.append).already_complete == 3 and again == []
