"""Campaign runs: the stored dataset is the same bit for bit however it ran (chunks, resume, Dask), replay, report."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import xarray as xr
from scipy import stats

from mrpctl import Spacecraft, simulate_batch
from mrpctl.campaign import open_campaign, parse_campaign, replay, report, run_campaign, run_inputs, write_report
from mrpctl.campaign.report import clopper_pearson_interval, figures, wilson_interval
from mrpctl.campaign.simulation import METRICS
from mrpctl.errors import SpecificationError

SPEC = {
    "name": "small",
    "count": 12,
    "seed": 3,
    "tau": 0.05,
    "rate": 100.0,
    "t_final": 3.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"k_sigma": -70.11, "k_omega": -163.08},
    "rule": {"type": "delay-aware"},
    "dispersions": {
        "attitude": {"angle_deg": [150.0, 180.0]},
        "omega": {"magnitude": [0.0, 0.5]},
        "tau": {"range": [0.04, 0.05], "step": 0.01},
        "gains": {"scale": [0.5, 1.5]},
    },
}


class Stop(Exception):
    """Raised by a progress callback to interrupt a campaign, as Ctrl-C would."""


@pytest.fixture(scope="module")
def spec():
    return parse_campaign(copy.deepcopy(SPEC))


@pytest.fixture(scope="module")
def reference(spec, tmp_path_factory):
    out = tmp_path_factory.mktemp("reference")
    result = run_campaign(spec, out, chunk=5, threads=1)
    assert result.complete and result.simulated == 3 and result.runs == 12
    return out, open_campaign(out)


def assert_bitwise_identical(a: xr.Dataset, b: xr.Dataset) -> None:
    xr.testing.assert_identical(a, b)
    for name in a.data_vars:
        assert a[name].values.tobytes() == b[name].values.tobytes(), name


def test_dataset_holds_inputs_metrics_and_spec(spec, reference):
    _out, dataset = reference
    assert dataset.sizes["run"] == 12
    assert set(METRICS) <= set(dataset.data_vars)
    assert {"sigma0", "omega0", "inertia", "tau", "gain_scale"} <= set(dataset.data_vars)
    assert json.loads(dataset.attrs["campaign"]) == SPEC
    assert dataset.attrs["seed"] == 3 and "casadi" in json.loads(dataset.attrs["versions"])
    inputs = run_inputs(spec, 0, 12)
    assert np.array_equal(dataset["sigma0"].values, inputs.sigma0)
    assert np.array_equal(dataset["tau"].values, inputs.tau)


def test_metrics_equal_an_independent_simulate_batch_call(spec, reference):
    """Each run's stored metrics equal simulate_batch of that run's inputs (with its trajectory for the torque)."""
    _, dataset = reference
    inputs = run_inputs(spec, 0, 12)
    for i in (0, 7, 11):
        batch = simulate_batch(
            Spacecraft(inputs.inertia[i]),
            inputs.gain_scale[i] * spec.base.K,
            inputs.x0[i],
            tau=float(inputs.tau[i]),
            rule=spec.base.rule,
            t_final=spec.base.t_final,
            rate=spec.base.rate,
            trajectories=True,
            threads=1,
        )
        run = batch.runs[0]
        assert int(dataset["switch_count"][i]) == run.switch_count
        assert bool(dataset["converged"][i]) == run.converged
        assert float(dataset["max_sigma"][i]) == run.max_sigma
        u = np.asarray(run.u)
        assert float(dataset["peak_torque"][i]) == np.max(np.abs(u))  # max_k |u_k|_inf, as the engine accumulates it


def test_chunk_size_does_not_change_the_result(spec, reference, tmp_path):
    run_campaign(spec, tmp_path, chunk=4, threads=2)
    assert_bitwise_identical(open_campaign(tmp_path), reference[1])


def test_interrupted_campaign_resumes_to_the_uninterrupted_result(spec, reference, tmp_path):
    done = []

    def stop_after_two(index: int, start: int, stop: int) -> None:
        done.append(index)
        if len(done) == 2:
            raise Stop

    with pytest.raises(Stop):
        run_campaign(spec, tmp_path, chunk=3, threads=1, on_chunk=stop_after_two)
    partial = open_campaign(tmp_path)
    assert partial.sizes["run"] == 6  # a running/interrupted campaign can be read: its complete chunks
    # simulate a chunk half-written when the process died: data written, flag not yet set
    from mrpctl.campaign.run import simulate_chunk
    from mrpctl.campaign.store import CampaignStore

    store = CampaignStore(tmp_path, spec)
    values = simulate_chunk(spec, 6, 9)
    values["max_sigma"] = np.full(3, 123.0)  # garbage that the resume must overwrite
    xr.Dataset({"max_sigma": (("run",), values["max_sigma"])}).to_zarr(
        str(store.path), region={"run": slice(6, 9)}, mode="r+", consolidated=False
    )
    assert open_campaign(tmp_path).sizes["run"] == 6
    resumed = run_campaign(spec, tmp_path, threads=1)
    assert resumed.already_complete == 2 and resumed.simulated == 2 and resumed.complete
    assert_bitwise_identical(open_campaign(tmp_path), reference[1])


def test_resume_refuses_another_campaign_or_chunk(spec, reference):
    out, _ = reference
    with pytest.raises(SpecificationError, match="chunk"):
        run_campaign(spec, out, chunk=7)
    other = parse_campaign({**copy.deepcopy(SPEC), "seed": 4})
    with pytest.raises(SpecificationError, match="another campaign"):
        run_campaign(other, out)


@pytest.mark.slow
def test_dask_local_cluster_equals_local(spec, reference, tmp_path):
    """2 worker processes of a Dask LocalCluster store the same dataset, bit for bit."""
    pytest.importorskip("distributed")
    result = run_campaign(spec, tmp_path, chunk=5, scheduler="local", workers=2)
    assert result.complete
    assert_bitwise_identical(open_campaign(tmp_path), reference[1])


def test_replay_equals_stored(reference, tmp_path):
    out, dataset = reference
    worst = int(dataset["run"][int(np.argmax(dataset["switch_count"].values))])
    result = replay(out, worst, trajectory=True)
    assert result.matches, result.mismatches
    assert result.trajectory is not None and result.trajectory.switch_count == int(dataset["switch_count"][worst])
    from mrpctl.campaign.report import save_replay_plot

    path = save_replay_plot(result, tmp_path / "replay.png")
    assert path.stat().st_size > 1000


def test_replay_detects_a_tampered_store(spec, tmp_path):
    run_campaign(spec, tmp_path, chunk=12, threads=1)
    from mrpctl.campaign.store import STORE_NAME

    xr.Dataset({"switch_count": (("run",), np.full(12, 99, dtype=np.int64))}).to_zarr(
        str(tmp_path / STORE_NAME), region={"run": slice(0, 12)}, mode="r+", consolidated=False
    )
    result = replay(tmp_path, 2)
    assert not result.matches and result.mismatches == ("switch_count",)
    with pytest.raises(SpecificationError, match="run"):
        replay(tmp_path, 12)


def test_wilson_and_clopper_pearson_intervals():
    """Endpoints checked against their defining equations (score test; binomial tails), not a copy of the formula."""
    for k, n in ((0, 10), (8, 10), (97, 100), (1000, 1000), (3, 7)):
        low, high = wilson_interval(k, n)
        p, z = k / n, stats.norm.ppf(0.975)
        for end in (low, high):
            if 0 < end < 1:
                assert (p - end) ** 2 == pytest.approx(z * z * end * (1 - end) / n, rel=1e-9)
        low, high = clopper_pearson_interval(k, n)
        if k > 0:
            assert stats.binom.sf(k - 1, n, low) == pytest.approx(0.025, rel=1e-9)
        else:
            assert low == 0.0
        if k < n:
            assert stats.binom.cdf(k, n, high) == pytest.approx(0.025, rel=1e-9)
        else:
            assert high == 1.0
        assert low <= p <= high


def test_report_table_figures_and_worst_cases(reference):
    out, dataset = reference
    summary = report(out, worst=3)
    k = int(dataset["converged"].sum())
    assert summary.converged == k and summary.complete == 12
    assert summary.wilson == wilson_interval(k, 12)
    assert len(summary.worst) == 3
    assert all(case.command == f"mrpctl campaign replay {out} --run {case.run}" for case in summary.worst)
    severity = [0 if c.reason == "diverged" else 1 if c.reason == "not settled" else 2 for c in summary.worst]
    assert severity == sorted(severity)
    figs = figures(dataset)
    assert figs["switch_count"].axes[0].get_yscale() in ("log", "linear")
    _result, paths = write_report(out, worst=3)
    assert all(p.exists() and p.stat().st_size > 0 for p in paths)
    assert "converged" in (out / "report" / "report.md").read_text()


def test_cli_run_report_replay(tmp_path, capsys):
    import argparse
    import tomllib

    from mrpctl.cli.campaign import add_parser

    spec_file = tmp_path / "c.toml"
    lines = [
        'name = "cli"',
        "count = 4",
        "seed = 1",
        "tau = 0.05",
        "rate = 100.0",
        "t_final = 1.0",
        "[spacecraft]",
        "inertia = [140.0, 100.0, 80.0]",
        "[gains]",
        "k_sigma = -70.11",
        "k_omega = -163.08",
        "[rule]",
        'type = "on-delayed"',
        "[dispersions.attitude]",
        "angle_deg = [170.0, 180.0]",
    ]
    spec_file.write_text("\n".join(lines) + "\n")
    assert tomllib.loads(spec_file.read_text())["count"] == 4
    parser = argparse.ArgumentParser(prog="mrpctl")
    add_parser(parser.add_subparsers(dest="command"))
    out = tmp_path / "out"
    for argv in (
        ["campaign", "run", str(spec_file), "--out", str(out), "--chunk", "2"],
        ["campaign", "report", str(out)],
        ["campaign", "replay", str(out), "--run", "3"],
    ):
        args = parser.parse_args(argv)
        assert args.handler(args) == 0
    text = capsys.readouterr().out
    assert "campaign complete" in text and "identical to the stored run" in text
    assert (out / "report" / "switch_count.png").exists()


def test_store_that_would_not_fit_is_refused_up_front(spec, tmp_path, monkeypatch):
    """The size estimate is checked before anything is written, and the message says the way out."""
    import shutil
    from collections import namedtuple

    from mrpctl.campaign.store import STORE_NAME, bytes_per_run

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**6, 10**6 - 100, 100))
    with pytest.raises(SpecificationError, match="smaller count"):
        run_campaign(spec, tmp_path, chunk=4)
    assert not (tmp_path / STORE_NAME).exists()
    # inputs: 19 floats (sigma0, omega0, inertia, tau, gain_scale, angle, rate) + 12 flight floats + 4 integers
    assert bytes_per_run() == 8 * (3 + 3 + 9 + 4) + 8 * (1 + 3 + 3 + 1 + 1 + 3) + 8 * 4 + 8 * 6 + 2 + 8


def test_worker_task_imports_no_storage_or_plotting_and_names_stay_bound():
    """A Dask worker unpickling the chunk task imports neither xarray, zarr nor matplotlib (bench/campaign_dask.py),
    and the package's lazily bound names are the functions (``report`` is not shadowed by its submodule)."""
    import subprocess
    import sys

    code = (
        "import sys, mrpctl.campaign._task as t; "
        "print(sorted(m for m in ('xarray', 'zarr', 'matplotlib') if m in sys.modules)); "
        "import mrpctl.campaign.report; from mrpctl.campaign import report, simulate_chunk; "
        "print(callable(report) and report.__module__, simulate_chunk is t.simulate_chunk)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "[]"
    assert out[1] == "mrpctl.campaign.report True"


RULES_SPEC = {
    **copy.deepcopy(SPEC),
    "name": "rules",
    "count": 9,
    "t_final": 2.0,
    "dispersions": {
        **copy.deepcopy(SPEC["dispersions"]),
        "rule": {"rules": ["on-delayed", "delay-aware", "hysteretic:0.1"]},
    },
}


def test_rule_dispersion_is_crossed_with_the_cases_and_reported_by_rule(tmp_path):
    """Run i is case i // 3 under rule i % 3: the cases are those of the campaign without the rule list, each
    run's metrics are simulate_batch's of that rule alone, and the report's per-rule rows count the dataset."""
    from mrpctl.flight import Hysteretic
    from mrpctl.switching import DelayAware, OnDelayed

    spec = parse_campaign(copy.deepcopy(RULES_SPEC))
    assert spec.rule_labels == ("on-delayed", "delay-aware", "hysteretic:0.1") and spec.cases == 3
    run_campaign(spec, tmp_path, chunk=4, threads=2)
    dataset = open_campaign(tmp_path)
    assert json.loads(dataset.attrs["rules"]) == list(spec.rule_labels)
    assert dataset["rule"].values.tolist() == [i % 3 for i in range(9)]
    assert dataset["case"].values.tolist() == [i // 3 for i in range(9)]
    plain = parse_campaign({**copy.deepcopy(RULES_SPEC), "dispersions": copy.deepcopy(SPEC["dispersions"])})
    cases = run_inputs(plain, 0, 3)
    for i in range(9):
        assert np.array_equal(dataset["sigma0"].values[i], cases.sigma0[i // 3])
        assert np.array_equal(dataset["omega0"].values[i], cases.omega0[i // 3])
    assert np.isnan(dataset["delta"].values[[0, 1, 3, 4]]).all() and (dataset["delta"].values[[2, 5, 8]] == 0.1).all()
    expected_rules = (OnDelayed(), DelayAware(), Hysteretic(0.1))
    for i in (0, 4, 8):
        batch = simulate_batch(
            Spacecraft(cases.inertia[i // 3]),
            cases.gain_scale[i // 3] * spec.base.K,
            cases.x0[i // 3],
            tau=float(cases.tau[i // 3]),
            rule=expected_rules[i % 3],
            t_final=spec.base.t_final,
            rate=spec.base.rate,
            threads=1,
        )
        for name in METRICS:
            assert np.asarray(getattr(batch, name))[0].tobytes() == dataset[name].values[i].tobytes(), (i, name)
    summary = report(dataset)
    assert [r.rule for r in summary.by_rule] == list(spec.rule_labels)
    for r, entry in enumerate(summary.by_rule):
        mine = dataset["rule"].values == r
        assert entry.runs == 3 and entry.converged == int(dataset["converged"].values[mine].sum())
        assert entry.switch_quantiles["max"] == float(dataset["switch_count"].values[mine].max())
        assert entry.wilson == wilson_interval(entry.converged, 3)
    assert "by rule" in str(summary) and "hysteretic:0.1" in str(summary)
    assert json.loads(json.dumps(summary.summary()))["by_rule"][2]["rule"] == "hysteretic:0.1"
    assert replay(tmp_path, 5).matches


FLIGHT_SPEC = {
    **copy.deepcopy(SPEC),
    "name": "flight",
    "count": 6,
    "t_final": 2.0,
    "tau": 0.05,
    "rule": {"type": "hysteretic", "delta": 0.05},
    "flight": {"u_max": 40.0, "saturation": "clip", "attitude_noise": 2e-3, "jitter": [0.02, 0.05]},
    "dispersions": {
        "attitude": {"angle_deg": [150.0, 180.0]},
        "omega": {"magnitude": [0.0, 0.5]},
        "hysteresis": {"delta": [0.0, 0.2]},
        "actuator": {"u_max": [20.0, 60.0]},
        "disturbance": {"magnitude": [0.5, 1.0]},
        "sensor": {"rate_noise": [1e-4, 1e-3], "gyro_bias": [1e-3, 2e-3]},
    },
}


def test_flight_dispersions_are_stored_and_a_replay_reproduces_each_run(tmp_path):
    """Each run's flight options are drawn from (seed, run), stored, simulated as given (an independent
    simulate_batch call with the models built by hand), and replayed bit for bit."""
    from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel

    spec = parse_campaign(copy.deepcopy(FLIGHT_SPEC))
    run_campaign(spec, tmp_path, chunk=4, threads=2)
    ds = open_campaign(tmp_path)
    delta, u_max = ds["delta"].values, ds["u_max"].values
    assert ((delta >= 0.0) & (delta <= 0.2)).all() and len(set(delta.tolist())) == 6
    assert ((u_max >= 20.0) & (u_max <= 60.0)).all() and (u_max == u_max[:, :1]).all()
    w = np.linalg.norm(ds["disturbance"].values, axis=1)
    assert ((w >= 0.5 * (1 - 1e-12)) & (w <= 1.0 * (1 + 1e-12))).all()
    bias = np.linalg.norm(ds["gyro_bias"].values, axis=1)
    assert ((bias >= 1e-3 * (1 - 1e-12)) & (bias <= 2e-3 * (1 + 1e-12))).all()
    assert (ds["attitude_noise"].values == 2e-3).all()
    assert len(set(ds["noise_seed"].values.tolist())) == 6 and len(set(ds["jitter_seed"].values.tolist())) == 6
    assert np.isfinite(ds["peak_torque"].values).all()
    inputs = run_inputs(spec, 0, 6)
    for i in (1, 4):
        batch = simulate_batch(
            Spacecraft(inputs.inertia[i]),
            inputs.gain_scale[i] * spec.base.K,
            inputs.x0[i],
            tau=0.05,
            rule=Hysteretic(float(delta[i])),
            t_final=2.0,
            rate=100.0,
            threads=1,
            actuator=ActuatorModel(u_max[i], mode=Saturation.CLIP),
            disturbance=Disturbance(ds["disturbance"].values[i]),
            sensor=SensorModel(
                2e-3, float(ds["rate_noise"].values[i]), ds["gyro_bias"].values[i], seed=int(ds["noise_seed"].values[i])
            ),
            delay=DelayModel.jitter(0.02, 0.05, seed=int(ds["jitter_seed"].values[i])),
        )
        for name in METRICS:
            assert np.asarray(getattr(batch, name))[0].tobytes() == ds[name].values[i].tobytes(), (i, name)
        result = replay(tmp_path, i, trajectory=True)
        assert result.matches, result.mismatches
        assert result.trajectory is not None and result.trajectory.switch_count == int(ds["switch_count"].values[i])
    # the stored noise seed is the one used: the replayed trajectory is the seed's, another seed's differs
    from mrpctl import simulate

    def trajectory(seed: int) -> np.ndarray:
        return simulate(
            Spacecraft(inputs.inertia[4]),
            inputs.gain_scale[4] * spec.base.K,
            inputs.x0[4],
            tau=0.05,
            rule=Hysteretic(float(delta[4])),
            t_final=2.0,
            rate=100.0,
            actuator=ActuatorModel(u_max[4], mode=Saturation.CLIP),
            disturbance=Disturbance(ds["disturbance"].values[4]),
            sensor=SensorModel(2e-3, float(ds["rate_noise"].values[4]), ds["gyro_bias"].values[4], seed=seed),
            delay=DelayModel.jitter(0.02, 0.05, seed=int(ds["jitter_seed"].values[4])),
        ).sigma

    assert np.array_equal(trajectory(int(ds["noise_seed"].values[4])), result.trajectory.sigma)
    assert not np.array_equal(trajectory(12345), result.trajectory.sigma)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"dispersions": {"rule": {"rules": ["hysteretic", "on-delayed"]}}}, "every rule must be 'hysteretic'"),
        ({"rule": {"type": "delay-aware"}}, "no rule of the campaign is 'hysteretic'"),
        ({"flight": {"jitter": [0.02, 0.04]}}, "tau_max must equal tau"),
        ({"flight": {"u_max": 1.0, "colour": 1}}, "unknown key 'colour'"),
        ({"flight": {"norm_max": 1.0}}, "need flight.u_max"),
        ({"dispersions": {"rule": {"rules": ["on-delayed", "on-delayed"]}}}, "listed twice"),
        ({"dispersions": {"rule": {"rules": ["on-delayed:3"]}}}, "takes no parameter"),
        ({"dispersions": {"hysteresis": {"delta": [0.0, 1.0]}}}, r"\[0, 1\)"),
        ({"dispersions": {"actuator": {"u_max": [0.0, 1.0]}}}, "must be > 0"),
        ({"rule": {"type": "hysteretic", "eps": 0.1}}, "takes delta only"),
        ({"rule": {"type": "on-predicted"}}, r"'on-predicted' needs a \[predictor\] table"),
        ({"dispersions": {"rule": {"rules": ["on-predicted", "hysteretic"]}}}, "every rule must be 'on-predicted'"),
        ({"predictor": {}}, r"\[predictor\] applies only with rule 'on-predicted'"),
    ],
)
def test_rule_and_flight_keys_are_checked(change, message):
    data = copy.deepcopy(FLIGHT_SPEC)
    for key, value in change.items():
        data[key] = value if key != "dispersions" else {**data["dispersions"], **value}
    with pytest.raises(SpecificationError, match=message):
        parse_campaign(data)


@pytest.mark.parametrize("name", ["tumble", "tumble_fixed_inertia", "rules", "flight", "predictor"])
def test_shipped_campaign_files_parse_and_sample(name):
    from pathlib import Path

    from mrpctl.campaign import load_campaign

    spec = load_campaign(Path(__file__).resolve().parent.parent / "examples" / "campaigns" / f"{name}.toml")
    inputs = run_inputs(spec, 0, min(4, spec.count))
    assert len(inputs) == min(4, spec.count) and np.isfinite(inputs.x0).all()
    assert inputs.rule.tolist() == [i % len(spec.rule_list) for i in range(len(inputs))]


def test_flight_runs_sharing_their_models_run_in_one_call_with_the_same_results(tmp_path):
    """Without per-run noise or jitter the flight runs share one simulate_batch call (on 2 threads); each run
    equals the same run simulated alone."""
    from mrpctl.campaign._task import simulate_chunk

    data = copy.deepcopy(FLIGHT_SPEC)
    data["flight"] = {"u_max": 40.0, "disturbance": [0.2, 0.0, -0.1]}
    data["dispersions"] = {k: data["dispersions"][k] for k in ("attitude", "omega", "hysteresis")}
    data["count"] = 4
    spec = parse_campaign(data)
    together = simulate_chunk(spec, 0, 4, threads=2)
    for i in range(4):
        alone = simulate_chunk(spec, i, i + 1, threads=1)
        for name, values in alone.items():
            assert values[0].tobytes() == together[name][i].tobytes(), (i, name)
    assert (together["u_max"] == 40.0).all() and (together["disturbance"] == [0.2, 0.0, -0.1]).all()


def test_a_store_of_another_noise_revision_is_not_resumed_and_its_replay_says_why(spec, tmp_path):
    """Runs with attitude noise depend on mrpctl.flight.NOISE_REVISION: a store written with another revision is
    not resumed (it would mix the two), and its replay names both revisions; a campaign without attitude noise is
    not concerned."""
    import zarr

    from mrpctl.campaign.store import STORE_NAME
    from mrpctl.flight import NOISE_REVISION

    noisy = parse_campaign(copy.deepcopy(FLIGHT_SPEC))
    assert noisy.attitude_noisy and not spec.attitude_noisy
    run_campaign(noisy, tmp_path / "noisy", chunk=3, threads=1)
    group = zarr.open_group(str(tmp_path / "noisy" / STORE_NAME), mode="r+")
    assert int(group.attrs["noise_revision"]) == NOISE_REVISION
    assert replay(tmp_path / "noisy", 1).noise_revisions is None
    group.attrs["noise_revision"] = NOISE_REVISION + 1
    with pytest.raises(SpecificationError, match=f"noise revision {NOISE_REVISION + 1}.*revision {NOISE_REVISION}"):
        run_campaign(noisy, tmp_path / "noisy", threads=1)
    result = replay(tmp_path / "noisy", 1)
    assert result.noise_revisions == (NOISE_REVISION + 1, NOISE_REVISION)
    assert f"noise revision {NOISE_REVISION + 1}" in str(result)
    # a campaign without attitude noise resumes whatever the revision (a store without the attribute is revision 1)
    run_campaign(spec, tmp_path / "plain", chunk=12, threads=1)
    group = zarr.open_group(str(tmp_path / "plain" / STORE_NAME), mode="r+")
    del group.attrs["noise_revision"]
    assert str(run_campaign(spec, tmp_path / "plain", threads=1)).startswith("campaign")
    assert replay(tmp_path / "plain", 0).noise_revisions is None
