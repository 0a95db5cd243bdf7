"""Campaigns of the tracking loop: the scenario's [reference] flown on every run, [dispersions.reference] drawn per
case, the pointing metrics stored, reported and replayed.

Every run is checked against ``simulate`` of the run's inputs with the reference built here from the guidance
classes (not by the campaign's code); the drawn slew angles, axes and orbit rates against their laws with
``scipy.stats.kstest``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_assertions import one_line_error
from scipy import stats
from scipy.spatial.transform import Rotation

from mrpctl import Spacecraft, simulate
from mrpctl.campaign import load_campaign, open_campaign, parse_campaign, replay, report, run_campaign, run_inputs
from mrpctl.campaign import simulation as campaign_simulation
from mrpctl.campaign._task import simulate_chunk
from mrpctl.campaign.report import figures
from mrpctl.campaign.simulation import METRICS, POINTING_METRICS
from mrpctl.cli import USER_ERROR, main
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.guidance import CircularOrbit, EigenaxisSlew, InertialPointing, NadirPointing, reference_samples
from mrpctl.simulation import kept_run_bytes

RATE, T_FINAL, TAU = 100.0, 25.0, 0.05
HEADER = f"""
name = "tracking"
count = 6
seed = 17
tau = {TAU}
rate = {RATE}
t_final = {T_FINAL}
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -560.0
k_omega = -1000.0
[rule]
type = "hysteretic"
delta = 0.05
"""
SLEW = """
[reference]
type = "slew"
axis = [0.0, 0.0, 1.0]
angle_deg = 90.0
rate_limit = 0.2
acceleration_limit = 0.05
t_start = 1.0
"""
NADIR = """
[reference]
type = "nadir"
altitude = 500e3
inclination_deg = 97.4
raan_deg = 30.0
"""


def _spec(text: str, tmp_path: Path | None = None) -> Any:
    if tmp_path is None:
        import tomllib

        return parse_campaign(tomllib.loads(text), name="tracking")
    path = tmp_path / "c.toml"
    path.write_text(text, encoding="utf-8")
    return load_campaign(path)


def _simulate_run(spec: Any, inputs: Any, j: int, reference: Any, **options: Any) -> Any:
    """Run j alone through simulate, its models written here from the stored inputs."""
    return simulate(
        Spacecraft(inputs.inertia[j]),
        inputs.gain_scale[j] * spec.base.K,
        inputs.x0[j],
        tau=float(inputs.tau[j]),
        rule=Hysteretic(0.05),
        t_final=T_FINAL,
        rate=RATE,
        reference=reference,
        **options,
    )


def _same(chunk: dict[str, np.ndarray], j: int, result: Any) -> None:
    """The chunk's row j equals the simulate result bit for bit (None is NaN)."""
    for name in [*METRICS, *POINTING_METRICS]:
        value = getattr(result, name)
        expected = np.asarray(np.nan if value is None else value, dtype=chunk[name].dtype)
        assert chunk[name][j].tobytes() == expected.tobytes(), (name, j, chunk[name][j], value)


def test_slew_campaign_runs_equal_simulate_of_their_inputs_and_each_run_alone() -> None:
    text = (
        HEADER
        + SLEW
        + """
[dispersions.reference]
slew_angle_deg = [30.0, 200.0]
slew_axis = "sphere"
[dispersions.omega]
magnitude = [0.0, 0.01]
"""
    )
    spec = _spec(text)
    chunk = simulate_chunk(spec, 0, spec.count, threads=2)
    inputs = run_inputs(spec, 0, spec.count)
    for j in range(spec.count):
        slew = EigenaxisSlew(
            start=[0.0, 0.0, 0.0],
            rate_limit=0.2,
            acceleration_limit=0.05,
            axis=inputs.slew_axis[j],
            angle=np.radians(inputs.slew_angle[j]),
            t_start=1.0,
        )
        _same(chunk, j, _simulate_run(spec, inputs, j, slew))
        alone = simulate_chunk(spec, j, j + 1, threads=1)
        for name, values in chunk.items():
            assert alone[name][0].tobytes() == values[j].tobytes(), (name, j)
    assert np.all((chunk["slew_angle"] >= 30.0) & (chunk["slew_angle"] <= 200.0))
    assert len(set(chunk["slew_angle"].tolist())) == spec.count  # drawn per run
    np.testing.assert_allclose(np.linalg.norm(chunk["slew_axis"], axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.all(np.isnan(chunk["orbit_rate"]))  # a slew has no orbit
    assert np.all(chunk["converged"]) and np.all(np.isfinite(chunk["pointing_max"]))
    assert np.all(chunk["slew_time"] < T_FINAL)


def _pointing_by_scipy(result: Any, profile: Any) -> tuple[float, float, float]:
    """(max, RMS after the settling time in deg, slew time in s) of a run, from its plant attitude and the
    reference's rows composed by scipy's rotations (Φ = |R_B/N R_R/N^-1|), with the metrics' definitions."""
    rows = reference_samples(profile, len(result.t), RATE)
    angle = np.degrees(
        (Rotation.from_mrp(np.array(result.sigma)) * Rotation.from_mrp(np.array(rows[:, 0:3])).inv()).magnitude()
    )
    after = angle[result.t >= result.settling_time]
    above = np.flatnonzero(angle >= 0.1)
    return float(after.max()), float(np.sqrt(np.mean(after**2))), float(result.t[above[-1] + 1])


def test_the_pointing_metrics_agree_with_scipys_rotations() -> None:
    spec = _spec(HEADER + SLEW + '[dispersions.reference]\nslew_angle_deg = [30.0, 200.0]\nslew_axis = "sphere"\n')
    chunk = simulate_chunk(spec, 0, 3, threads=1)
    inputs = run_inputs(spec, 0, 3)
    for j in range(3):
        slew = EigenaxisSlew(
            start=[0.0, 0.0, 0.0],
            rate_limit=0.2,
            acceleration_limit=0.05,
            axis=inputs.slew_axis[j],
            angle=np.radians(inputs.slew_angle[j]),
            t_start=1.0,
        )
        peak, rms, slew_time = _pointing_by_scipy(_simulate_run(spec, inputs, j, slew), slew)
        assert chunk["pointing_max"][j] == pytest.approx(peak, rel=1e-9)
        assert chunk["pointing_rms"][j] == pytest.approx(rms, rel=1e-9)
        assert chunk["slew_time"][j] == slew_time
        assert 0.0 < chunk["pointing_rms"][j] <= chunk["pointing_max"][j] < 0.1


def test_nadir_campaign_with_a_flight_model_and_crossed_rules_equals_simulate() -> None:
    text = (
        HEADER.replace('type = "hysteretic"\ndelta = 0.05\n', 'type = "hysteretic"\ndelta = 0.05\n')
        + NADIR
        + """
[flight]
u_max = 5.0
[dispersions.reference]
orbit_rate = {distribution = "truncnorm", mean = 1.1e-3, std = 3e-4, low = 5e-4, high = 2e-3}
[dispersions.attitude]
angle_deg = [0.0, 20.0]
"""
    )
    spec = _spec(text)
    chunk = simulate_chunk(spec, 0, spec.count, threads=2)
    inputs = run_inputs(spec, 0, spec.count)
    for j in range(spec.count):
        nadir = NadirPointing(
            CircularOrbit(float(inputs.orbit_rate[j]), inclination=math.radians(97.4), raan=math.radians(30.0))
        )
        result = _simulate_run(spec, inputs, j, nadir, actuator=ActuatorModel(5.0))
        _same(chunk, j, result)
    assert np.all((chunk["orbit_rate"] >= 5e-4) & (chunk["orbit_rate"] <= 2e-3))
    assert np.all(np.isnan(chunk["slew_angle"])) and np.all(np.isnan(chunk["slew_axis"]))


def test_an_undispersed_reference_is_shared_and_stored_with_its_base_values() -> None:
    spec = _spec(HEADER + '\n[reference]\ntype = "inertial"\nsigma = [0.1, -0.2, 0.05]\n')
    chunk = simulate_chunk(spec, 0, 3, threads=1)
    inputs = run_inputs(spec, 0, 3)
    for j in range(3):
        _same(chunk, j, _simulate_run(spec, inputs, j, InertialPointing([0.1, -0.2, 0.05])))
    assert np.all(np.isnan(chunk["slew_angle"])) and np.all(np.isnan(chunk["orbit_rate"]))
    spec = _spec(HEADER + SLEW)
    values = run_inputs(spec, 0, 3)
    assert np.all(values.slew_angle == 90.0) and np.all(values.slew_axis == [0.0, 0.0, 1.0])


def test_groups_bounded_by_memory_give_the_same_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    spec = _spec(HEADER + SLEW + "[dispersions.reference]\nslew_angle_deg = [30.0, 120.0]\n")
    n = math.floor(T_FINAL * RATE + 1e-9) + 1
    per_run = kept_run_bytes(T_FINAL, RATE, 1, records=True)
    assert per_run >= n * (104 + 256)  # the kept sample (m_k, u_k, t, omega) and its flight records, per sample
    assert campaign_simulation._group_size(T_FINAL, RATE, 1) == int(campaign_simulation.TRACKING_BATCH_BYTES // per_run)
    whole = simulate_chunk(spec, 0, spec.count, threads=2)
    monkeypatch.setattr(campaign_simulation, "TRACKING_BATCH_BYTES", 2.5 * per_run)  # 2 runs per call
    assert campaign_simulation._group_size(T_FINAL, RATE, 1) == 2
    calls: list[int] = []
    real = campaign_simulation.simulate_batch

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(len(kwargs["reference"]))
        return real(*args, **kwargs)

    monkeypatch.setattr(campaign_simulation, "simulate_batch", counted)
    grouped = simulate_chunk(spec, 0, spec.count, threads=2)
    assert calls == [2, 2, 2]
    for name, values in whole.items():
        assert grouped[name].tobytes() == values.tobytes(), name


def test_the_reference_draws_follow_their_laws_and_move_no_other_draw() -> None:
    count = 4000
    text = (
        HEADER.replace("count = 6", f"count = {count}")
        + SLEW
        + """
[dispersions.reference]
slew_angle_deg = {distribution = "truncnorm", mean = 90.0, std = 40.0, low = 10.0, high = 180.0}
slew_axis = "sphere"
[dispersions.attitude]
angle_deg = [0.0, 180.0]
"""
    )
    spec = _spec(text)
    inputs = run_inputs(spec, 0, count)
    a, b = (10.0 - 90.0) / 40.0, (180.0 - 90.0) / 40.0
    assert stats.kstest(inputs.slew_angle, stats.truncnorm(a, b, loc=90.0, scale=40.0).cdf).pvalue > 1e-3
    assert stats.kstest(inputs.slew_angle, stats.uniform(10.0, 170.0).cdf).pvalue < 1e-10  # power: not uniform
    axis = inputs.slew_axis
    np.testing.assert_allclose(np.linalg.norm(axis, axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.all(np.abs(axis.mean(axis=0)) < 4.0 / math.sqrt(3.0 * count))  # mean 0, sd 1/sqrt(3N)
    np.testing.assert_allclose(axis.T @ axis / count, np.eye(3) / 3.0, atol=0.03)  # second moment I/3
    for k in range(3):  # Archimedes: each component of a uniform unit vector is uniform on [-1, 1]
        assert stats.kstest(axis[:, k], stats.uniform(-1.0, 2.0).cdf).pvalue > 1e-3
    # a uniform orbit rate on a nadir campaign
    nadir = _spec(
        HEADER.replace("count = 6", f"count = {count}")
        + NADIR
        + "[dispersions.reference]\norbit_rate = [8e-4, 1.2e-3]\n"
    )
    rates = run_inputs(nadir, 0, count).orbit_rate
    assert stats.kstest(rates, stats.uniform(8e-4, 4e-4).cdf).pvalue > 1e-3
    # the reference stream is the case's third: the attitudes are those of the campaign without it
    plain = _spec(HEADER.replace("count = 6", f"count = {count}") + SLEW + "[dispersions.attitude]\n")
    before = run_inputs(plain, 0, count)
    assert before.sigma0.tobytes() == inputs.sigma0.tobytes()
    assert before.noise_seed.tobytes() == inputs.noise_seed.tobytes()


def test_rules_crossed_with_the_cases_fly_the_same_reference() -> None:
    text = HEADER + SLEW + "[dispersions.reference]\nslew_angle_deg = [30.0, 180.0]\n[dispersions.rule]\n"
    text += 'rules = ["hysteretic:0.0", "hysteretic:0.2"]\n'
    inputs = run_inputs(_spec(text), 0, 6)
    assert inputs.slew_angle[0::2].tobytes() == inputs.slew_angle[1::2].tobytes()
    assert len(set(inputs.slew_angle[0::2].tolist())) == 3


def test_store_report_and_replay_of_a_tracking_campaign(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows_path = tmp_path / "rows.csv"
    n = math.floor(T_FINAL * RATE + 1e-9) + 1
    profile = EigenaxisSlew(
        start=[0.0, 0.0, 0.0], rate_limit=0.2, acceleration_limit=0.05, axis=[0.0, 0.6, 0.8], angle=math.radians(120.0)
    )
    rows = reference_samples(profile, n, RATE)
    np.savetxt(rows_path, rows, delimiter=",", fmt="%.17g")
    np.savetxt(rows_path.with_name("copy.csv"), rows, delimiter=",", fmt="%.17g")
    path = tmp_path / "c.toml"
    path.write_text(HEADER + '\n[reference]\ntype = "file"\nfile = "rows.csv"\n', encoding="utf-8")
    spec = load_campaign(path)
    out = tmp_path / "out"
    run_campaign(spec, out, chunk=4)
    rows_path.unlink()  # the store holds the rows: a replay never reads the file
    dataset = open_campaign(out)
    assert dataset["pointing_max"].attrs["units"] == "deg" and dataset["slew_time"].attrs["units"] == "s"
    assert dataset["slew_angle"].attrs["units"] == "deg" and dataset["orbit_rate"].attrs["units"] == "rad/s"
    assert (
        dataset["reference_rows"].values.tobytes()
        == np.loadtxt(rows_path.with_name("copy.csv"), delimiter=",").tobytes()
    )
    inputs = run_inputs(spec, 0, spec.count)
    stored = {name: np.asarray(dataset[name].values) for name in [*METRICS, *POINTING_METRICS]}
    for j in (0, 5):
        _same(stored, j, _simulate_run(spec, inputs, j, rows))
    again = replay(out, 5)
    assert again.matches, again.mismatches
    assert "pointing_max" in again.stored
    summary = report(out)
    text = str(summary)
    assert "pointing max after settling (deg)" in text and "slew time (s)" in text
    assert summary.pointing is not None and summary.pointing["slewed"] == int(np.isfinite(dataset["slew_time"]).sum())
    assert summary.pointing["pointing_max_deg"]["max"] == float(np.nanmax(dataset["pointing_max"].values))
    json.dumps(summary.summary()["pointing"])
    assert main(["campaign", "report", str(out)]) == 0
    assert "pointing RMS after settling (deg)" in capsys.readouterr().out
    assert "point_max_deg" in text and "slew_time_s" in text  # the worst cases' pointing columns
    first = summary.worst[0]
    assert first.slew_time == float(dataset["slew_time"].sel(run=first.run))
    written = json.loads((out / "report" / "summary.json").read_text(encoding="utf-8"))
    assert "pointing_max" in written["worst"][0]
    assert written["pointing"]["slew_time_s"]["max"] == float(np.nanmax(dataset["slew_time"].values))
    assert (out / "report" / "pointing.png").stat().st_size > 0
    # a resume whose file now holds other rows is refused, naming the key and the file
    other = reference_samples(
        EigenaxisSlew(start=[0.0] * 3, rate_limit=0.2, acceleration_limit=0.05, axis=[1.0, 0, 0], angle=1.0), n, RATE
    )
    np.savetxt(rows_path, other, delimiter=",", fmt="%.17g")
    with pytest.raises(SpecificationError, match=r"\[reference\] file: .*rows.csv is not the file"):
        run_campaign(load_campaign(path), out, chunk=4)


def test_a_regulation_campaign_stores_no_tracking_arrays(tmp_path: Path) -> None:
    spec = _spec(HEADER.replace("count = 6", "count = 2"))
    chunk = simulate_chunk(spec, 0, 2, threads=1)
    assert not set(chunk) & {"slew_angle", "slew_axis", "orbit_rate", *POINTING_METRICS}
    run_campaign(spec, tmp_path / "out", chunk=2)
    assert "pointing_max" not in open_campaign(tmp_path / "out")
    assert report(tmp_path / "out").pointing is None
    assert "pointing" not in figures(tmp_path / "out")
    assert "pointing_max" not in report(tmp_path / "out").summary()["worst"][0]


BAD = [
    ("\n[dispersions.reference]\nslew_angle_deg = [10.0, 20.0]\n", "[dispersions.reference] disperses the reference"),
    (SLEW + "[dispersions.reference]\norbit_rate = [1e-3, 2e-3]\n", "dispersions.reference.orbit_rate applies to"),
    (
        NADIR + "[dispersions.reference]\nslew_angle_deg = [10.0, 20.0]\n",
        "dispersions.reference.slew_angle_deg applies",
    ),
    (NADIR + '[dispersions.reference]\nslew_axis = "sphere"\n', "dispersions.reference.slew_axis applies"),
    (NADIR + "[dispersions.reference]\norbit_rate = [-1e-3, 2e-3]\n", "dispersions.reference.orbit_rate: every draw"),
    (
        NADIR + "[dispersions.reference]\norbit_rate = {distribution = 'normal', mean = 1e-3, std = 1e-4}\n",
        "dispersions.reference.orbit_rate: every draw",
    ),
    (SLEW + "[dispersions.reference]\nslew_angle_deg = [0.0, 90.0]\n", "dispersions.reference.slew_angle_deg"),
    (SLEW + "[dispersions.reference]\nslew_angle_deg = [90.0, 400.0]\n", "dispersions.reference.slew_angle_deg"),
    (SLEW + '[dispersions.reference]\nslew_axis = "cube"\n', "dispersions.reference.slew_axis must be"),
    (SLEW + "[dispersions.reference]\nslew_rate = [0.1, 0.2]\n", "unknown key 'slew_rate' in [dispersions.reference]"),
    (
        '\n[reference]\ntype = "inertial"\nsigma = [0.1, 0.0, 0.0]\n[dispersions.reference]\nslew_axis = "sphere"\n',
        "dispersions.reference.slew_axis applies",
    ),
]


@pytest.mark.parametrize(("extra", "needle"), BAD)
def test_bad_reference_dispersions_are_refused_naming_the_key(extra: str, needle: str) -> None:
    with pytest.raises(SpecificationError) as error:
        _spec(HEADER + extra)
    assert needle in str(error.value)


def test_a_plant_side_rule_is_refused_with_a_reference() -> None:
    with pytest.raises(SpecificationError, match=r"\[reference\].*'delay-aware'"):
        _spec(HEADER.replace('type = "hysteretic"\ndelta = 0.05', 'type = "delay-aware"') + SLEW)
    text = HEADER + SLEW + '[dispersions.rule]\nrules = ["hysteretic:0.1", "on-current"]\n'
    with pytest.raises(SpecificationError, match=r"\[reference\].*'on-current'"):
        _spec(text)


def test_cli_prints_one_line_and_exits_2_on_a_bad_reference_dispersion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "c.toml"
    path.write_text(HEADER + NADIR + "[dispersions.reference]\norbit_rate = [-1e-3, 2e-3]\n", encoding="utf-8")
    assert main(["campaign", "run", str(path), "--out", str(tmp_path / "out")]) == USER_ERROR == 2
    one_line_error(capsys, "dispersions.reference.orbit_rate", ">")
    assert not (tmp_path / "out").exists()
    path.write_text(HEADER + "[dispersions.reference]\nslew_axis = 'sphere'\n", encoding="utf-8")
    assert main(["campaign", "run", str(path), "--out", str(tmp_path / "out")]) == 2
    one_line_error(capsys, "[dispersions.reference]", "[reference]")


def test_the_example_tracking_campaign_parses_and_its_first_run_equals_simulate() -> None:
    path = Path(__file__).resolve().parent.parent / "examples" / "campaigns" / "tracking" / "slew.toml"
    spec = load_campaign(path)
    assert spec.tracking and spec.reference is not None and spec.reference.slew_axis
    assert spec.reference.slew_angle_deg is not None


def test_a_predictor_campaign_tracks_each_runs_orbit_as_simulate_does() -> None:
    """The predictor (its model the nominal spacecraft, the plant dispersed) on a dispersed nadir reference."""
    from mrpctl.predictor import OnPredicted, Predictor

    text = HEADER.replace('type = "hysteretic"\ndelta = 0.05', 'type = "on-predicted"') + NADIR
    text += "[predictor]\n[dispersions.reference]\norbit_rate = [5e-4, 2e-3]\n[dispersions.inertia]\n"
    text += "axis_tolerance = 0.1\n[dispersions.attitude]\nangle_deg = [0.0, 30.0]\n"
    spec = _spec(text.replace("count = 6", "count = 3"))
    chunk = simulate_chunk(spec, 0, 3, threads=1)
    inputs = run_inputs(spec, 0, 3)
    model = Spacecraft([140.0, 100.0, 80.0])
    for j in range(3):
        nadir = NadirPointing(
            CircularOrbit(float(inputs.orbit_rate[j]), inclination=math.radians(97.4), raan=math.radians(30.0))
        )
        result = simulate(
            Spacecraft(inputs.inertia[j]),
            spec.base.K,
            inputs.x0[j],
            tau=TAU,
            rule=OnPredicted(1.0),
            t_final=T_FINAL,
            rate=RATE,
            predictor=Predictor(model),
            reference=nadir,
        )
        _same(chunk, j, result)
    assert len(set(chunk["orbit_rate"].tolist())) == 3


@pytest.mark.slow
def test_dask_workers_fly_the_stored_reference_rows_and_the_drawn_slews(tmp_path: Path) -> None:
    """A LocalCluster stores what the local runner stores: the file reference's rows are shipped with the task (the
    file deleted before the run) and the drawn slews come from (seed, case) on the worker.

    One cluster (one worker process, the settings of ``scheduler="local"``) serves both campaigns, as a
    cluster given by its address does: starting its worker is most of the test's time, and what is
    checked is what the task carries to a worker. ``scheduler="local"`` itself is run in test_campaign
    and test_campaign_files."""
    pytest.importorskip("distributed")
    import dask
    from dask.distributed import LocalCluster

    from mrpctl.campaign.run import LOCAL_CLUSTER_CONFIG

    n = math.floor(T_FINAL * RATE + 1e-9) + 1
    profile = EigenaxisSlew(
        start=[0.0, 0.0, 0.0], rate_limit=0.2, acceleration_limit=0.05, axis=[0.6, 0.0, 0.8], angle=math.radians(60.0)
    )
    np.savetxt(tmp_path / "rows.csv", reference_samples(profile, n, RATE), delimiter=",", fmt="%.17g")
    (tmp_path / "file.toml").write_text(
        HEADER + '\n[reference]\ntype = "file"\nfile = "rows.csv"\n[dispersions.omega]\nmagnitude = [0.0, 0.01]\n',
        encoding="utf-8",
    )
    (tmp_path / "slew.toml").write_text(
        HEADER + SLEW + '[dispersions.reference]\nslew_angle_deg = [30.0, 150.0]\nslew_axis = "sphere"\n',
        encoding="utf-8",
    )
    specs = [load_campaign(tmp_path / "file.toml"), load_campaign(tmp_path / "slew.toml")]
    (tmp_path / "rows.csv").unlink()
    with dask.config.set(LOCAL_CLUSTER_CONFIG):
        cluster = LocalCluster(
            n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None, memory_limit=0
        )
    with cluster:
        for k, spec in enumerate(specs):
            run_campaign(spec, tmp_path / f"local{k}", chunk=3, threads=1)
            assert run_campaign(spec, tmp_path / f"dask{k}", chunk=3, scheduler=cluster.scheduler_address).complete
    for k in range(len(specs)):
        local, worker = open_campaign(tmp_path / f"local{k}"), open_campaign(tmp_path / f"dask{k}")
        assert set(local.data_vars) == set(worker.data_vars) >= {"pointing_max", "slew_time", "slew_angle"}
        for name in local.data_vars:
            assert local[name].values.tobytes() == worker[name].values.tobytes(), name


def test_the_how_to_section_runs_as_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/how-to/campaigns.md's section on tracking campaigns: its Python block runs, its assertions hold."""
    page = (Path(__file__).resolve().parents[1] / "docs" / "how-to" / "campaigns.md").read_text(encoding="utf-8")
    section = page.split("## Campaigns of the tracking loop", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "docs/how-to/campaigns.md", "exec"), {})
    assert (tmp_path / "slews" / "campaign.zarr").is_dir()


def test_the_scenarios_tracking_options_reach_every_run(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the scenario reader gives a tracking scenario's options (Scenario.tracking_options), the runs take them."""
    from mrpctl.scenario import Scenario

    spec = _spec(HEADER + SLEW + '[dispersions.reference]\nslew_axis = "sphere"\n')
    plain = simulate_chunk(spec, 0, 2, threads=1)
    options = {"feedforward": True, "pointing_tolerance": 0.05}
    monkeypatch.setattr(Scenario, "tracking_options", property(lambda self: dict(options)), raising=False)
    chunk = simulate_chunk(spec, 0, 2, threads=1)
    inputs = run_inputs(spec, 0, 2)
    for j in range(2):
        slew = EigenaxisSlew(
            start=[0.0, 0.0, 0.0], rate_limit=0.2, acceleration_limit=0.05, axis=inputs.slew_axis[j],
            angle=math.radians(90.0), t_start=1.0,
        )  # fmt: skip
        _same(chunk, j, _simulate_run(spec, inputs, j, slew, **options))
    assert chunk["pointing_max"].tobytes() != plain["pointing_max"].tobytes()  # the feedforward flies


def test_a_slew_given_by_target_keeps_its_angle_and_takes_the_drawn_axis() -> None:
    from mrpctl.campaign._task import run_tracking

    text = HEADER + '\n[reference]\ntype = "slew"\ntarget = [0.0, 0.0, 0.41421356237309503]\nrate_limit = 0.2\n'
    text += 'acceleration_limit = 0.05\n[dispersions.reference]\nslew_axis = "sphere"\n'
    spec = _spec(text)
    inputs = run_inputs(spec, 0, 3)
    base = spec.base.reference
    assert base.angle == pytest.approx(math.pi / 2, rel=1e-12)  # tan(Φ/4) = √2 − 1: a quarter turn
    np.testing.assert_array_equal(inputs.slew_angle, np.full(3, math.degrees(base.angle)))
    for j in range(3):
        slew = run_tracking(spec, inputs, j)
        assert isinstance(slew, EigenaxisSlew) and slew.angle == base.angle and slew.target is None
        # the stored unit axis, normalised once more by the profile (to the last bit of |axis| = 1)
        np.testing.assert_array_equal(slew.axis, inputs.slew_axis[j] / np.linalg.norm(inputs.slew_axis[j]))
        np.testing.assert_allclose(slew.axis, inputs.slew_axis[j], rtol=0, atol=4e-16)
