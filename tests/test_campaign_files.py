"""Per-sample files in campaign TOML (issue 10): ``[flight] disturbance_file`` and ``delay_file``; and runs that
differ only in their constant torque (one ``simulate_batch`` call for them).

Each campaign is checked against an independent ``simulate_batch`` call (and ``simulate`` for one run)
given the same per-sample torque W_k + w_i (written here in NumPy) or the same delay sequence; the
store holds the files' numbers, so a replay never reads the file again.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl import Spacecraft, simulate, simulate_batch
from mrpctl.campaign import load_campaign, open_campaign, replay, run_campaign, run_inputs
from mrpctl.campaign._task import chunk_on_worker, simulate_chunk
from mrpctl.campaign.simulation import METRICS
from mrpctl.campaign.store import CampaignStore
from mrpctl.cli import USER_ERROR, main
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import DelayModel, Disturbance, Hysteretic, newest_arrived

RATE, T_FINAL, TAU, DELTA = 100.0, 2.0, 0.05, 0.05
N = 201  # floor(T_FINAL * RATE) + 1
ROWS = np.column_stack((4.0 * np.sin(np.arange(N) / 9.0), np.linspace(-3.0, 3.0, N), np.full(N, 1.5)))
DELAYS = (1 + (np.arange(N) * 3) % 5) / RATE  # 0.01 .. 0.05 s, whole periods, overtaking measurements

HEADER = f"""
name = "files"
count = 6
seed = 11
tau = {TAU}
rate = {RATE}
t_final = {T_FINAL}
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -7.011
k_omega = -16.308
[rule]
type = "hysteretic"
delta = {DELTA}
[dispersions.attitude]
angle_deg = [150.0, 180.0]
[dispersions.omega]
magnitude = [1.0, 3.0]
"""


def _csv(path: Path, array: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, array, delimiter=",", fmt="%.17g", header="written by the test")
    return path


def _campaign(folder: Path, flight: str, extra: str = "") -> Path:
    """A campaign file in ``folder`` (its per-sample files named relative to it)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "c.toml"
    path.write_text(HEADER + "[flight]\n" + flight + extra, encoding="utf-8")
    return path


def _metrics(batch: Any, i: int) -> dict[str, bytes]:
    return {name: np.asarray(getattr(batch, name))[i].tobytes() for name in METRICS}


def _independent_batch(spec: Any, **options: Any) -> Any:
    """The campaign's runs as one simulate_batch call with the models written by hand."""
    inputs = run_inputs(spec, 0, spec.count)
    return simulate_batch(
        [Spacecraft(J) for J in inputs.inertia],
        inputs.gain_scale[:, None, None] * spec.base.K[None],
        inputs.x0,
        tau=TAU,
        rule=Hysteretic(DELTA),
        t_final=T_FINAL,
        rate=RATE,
        threads=1,
        **options,
    ), inputs


def test_disturbance_file_is_added_to_each_runs_constant_and_dispersed_torque(tmp_path: Path) -> None:
    _csv(tmp_path / "data" / "w.csv", ROWS)
    path = _campaign(
        tmp_path / "case",
        'disturbance = [0.5, 0.0, -0.25]\ndisturbance_file = "../data/w.csv"\n',
        "[dispersions.disturbance]\nmagnitude = [1.0, 2.0]\n",
    )
    spec = load_campaign(path)  # the name is relative to the campaign file, not to the working directory
    assert spec.flight is not None and spec.flight.disturbance_file is not None
    assert spec.flight.disturbance_file.values.tobytes() == ROWS.tobytes()
    out = tmp_path / "out"
    run_campaign(spec, out, chunk=4, threads=2)
    ds = open_campaign(out)
    w = ds["disturbance"].values  # each run's constant torque: flight.disturbance + its dispersed draw
    assert len({tuple(row) for row in w.tolist()}) == 6
    dispersed = np.linalg.norm(w - [0.5, 0.0, -0.25], axis=1)
    assert ((dispersed >= 1.0 - 1e-12) & (dispersed <= 2.0 + 1e-12)).all()
    # independent: one call with a per-run list of torques W_k + w_i (another path of simulate_batch)
    assert (ds["switch_count"].values >= 1).sum() >= 2  # tumbles through 180 deg: the switch metrics are compared too
    batch, inputs = _independent_batch(spec, disturbance=[ROWS + w[i] for i in range(6)])
    for i in range(6):
        assert _metrics(batch, i) == {name: ds[name].values[i].tobytes() for name in METRICS}, i
    k = int(np.argmax(ds["switch_count"].values))  # a run that switches, simulated alone
    alone = simulate(
        Spacecraft(inputs.inertia[k]),
        inputs.gain_scale[k] * spec.base.K,
        inputs.x0[k],
        tau=TAU,
        rule=Hysteretic(DELTA),
        t_final=T_FINAL,
        rate=RATE,
        disturbance=Disturbance(ROWS + w[k]),
    )
    assert alone.switch_count == int(ds["switch_count"].values[k]) >= 1
    assert np.float64(alone.first_switch_time).tobytes() == ds["first_switch_time"].values[k].tobytes()
    assert np.float64(alone.max_sigma).tobytes() == ds["max_sigma"].values[k].tobytes()
    assert np.float64(alone.peak_torque).tobytes() == ds["peak_torque"].values[k].tobytes()
    # the file matters: the same campaign without it flies other runs
    plain = _campaign(
        tmp_path / "plain", "disturbance = [0.5, 0.0, -0.25]\n", "[dispersions.disturbance]\nmagnitude = [1.0, 2.0]\n"
    )
    without = simulate_chunk(load_campaign(plain), 0, 6)
    assert (without["disturbance"] == w).all() and not np.array_equal(without["max_sigma"], ds["max_sigma"].values)


def test_disturbance_file_alone_equals_the_shared_rows(tmp_path: Path) -> None:
    """Without a constant torque every run flies the file's rows themselves (one shared array)."""
    np.save(tmp_path / "w.npy", ROWS)
    spec = load_campaign(_campaign(tmp_path, 'disturbance_file = "w.npy"\n'))
    got = simulate_chunk(spec, 0, 6, threads=2)
    batch, _ = _independent_batch(spec, disturbance=ROWS)
    for i in range(6):
        assert _metrics(batch, i) == {name: got[name][i].tobytes() for name in METRICS}, i
    assert (got["disturbance"] == 0.0).all()


def test_delay_file_gives_the_runs_the_sequence(tmp_path: Path) -> None:
    _csv(tmp_path / "d.csv", DELAYS)
    spec = load_campaign(_campaign(tmp_path, 'delay_file = "d.csv"\nattitude_noise = 1e-3\n'))
    assert spec.flight is not None and spec.flight.delay_sequence is not None
    got = simulate_chunk(spec, 0, 6, threads=2)
    inputs = run_inputs(spec, 0, 6)
    sequence = DelayModel.sequence(DELAYS, tau_min=1.0 / RATE, tau_max=TAU)
    from mrpctl.flight import SensorModel

    for i in (0, 4):  # noise seeded per run: one independent call per run
        sensor = SensorModel(1e-3, 0.0, np.zeros(3), seed=int(got["noise_seed"][i]))
        batch = simulate_batch(
            Spacecraft(inputs.inertia[i]),
            inputs.gain_scale[i] * spec.base.K,
            inputs.x0[i],
            tau=TAU,
            rule=Hysteretic(DELTA),
            t_final=T_FINAL,
            rate=RATE,
            threads=1,
            sensor=sensor,
            delay=sequence,
        )
        assert _metrics(batch, 0) == {name: got[name][i].tobytes() for name in METRICS}, i
    alone = simulate(
        Spacecraft(inputs.inertia[4]),
        inputs.gain_scale[4] * spec.base.K,
        inputs.x0[4],
        tau=TAU,
        rule=Hysteretic(DELTA),
        t_final=T_FINAL,
        rate=RATE,
        sensor=SensorModel(1e-3, 0.0, np.zeros(3), seed=int(got["noise_seed"][4])),
        delay=sequence,
    )
    assert alone.switch_count == int(got["switch_count"][4])
    assert np.float64(alone.max_sigma).tobytes() == got["max_sigma"][4].tobytes()
    _, used = newest_arrived(np.rint(DELAYS * RATE).astype(np.int64), history=5)
    assert alone.delay_used is not None and alone.delay_used.tolist() == used.tolist()
    # the sequence matters: the constant delay tau flies other runs
    constant = simulate_chunk(load_campaign(_campaign(tmp_path / "constant", "attitude_noise = 1e-3\n")), 0, 6)
    assert not np.array_equal(constant["max_sigma"], got["max_sigma"])


def test_store_holds_the_numbers_so_replay_needs_no_file_and_resume_refuses_a_changed_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    torque = _csv(tmp_path / "w.csv", ROWS)
    delays = _csv(tmp_path / "d.csv", DELAYS)
    path = _campaign(tmp_path, 'disturbance_file = "w.csv"\ndelay_file = "d.csv"\ndisturbance = [0.0, 0.3, 0.0]\n')
    spec = load_campaign(path)
    out = tmp_path / "out"
    first = run_campaign(spec, out, chunk=4, threads=1, on_chunk=lambda index, start, stop: None)
    assert first.complete
    ds = open_campaign(out)
    assert ds["flight_disturbance_rows"].values.tobytes() == ROWS.tobytes()
    assert ds["flight_delays"].values.tobytes() == DELAYS.tobytes()
    files = spec.files
    assert files["disturbance_file"].sha256 == hashlib.sha256(ROWS.tobytes()).hexdigest()
    assert files["delay_file"].sha256 == hashlib.sha256(DELAYS.tobytes()).hexdigest()
    # the files edited and then deleted, the working directory elsewhere: replay still reproduces every run
    old_hash = files["disturbance_file"].sha256
    _csv(torque, 2.0 * ROWS)
    with pytest.raises(SpecificationError, match="not the file this campaign was started with") as caught:
        CampaignStore(out, load_campaign(path))
    new_hash = hashlib.sha256((2.0 * ROWS).tobytes()).hexdigest()
    assert "flight.disturbance_file" in str(caught.value) and str(torque) in str(caught.value)
    assert old_hash in str(caught.value) and new_hash in str(caught.value)
    torque.unlink()
    delays.unlink()
    monkeypatch.chdir(tmp_path.parent)
    for run in (0, 5):
        result = replay(out, run, trajectory=run == 5)
        assert result.matches, result.mismatches
    assert result.trajectory is not None and result.trajectory.switch_count == int(ds["switch_count"].values[5])
    # the Dask task gets the numbers with the chunk and never reads the files
    shipped = chunk_on_worker(spec.source, spec.base.name, 2, 6, spec.files)
    for name in METRICS:
        assert shipped[name].tobytes() == ds[name].values[2:6].tobytes(), name
    assert "disturbance_file" in str(spec) and files["delay_file"].sha256[:12] in str(spec)
    # stored numbers that no longer match their recorded hash are refused, not replayed
    import zarr

    rows = zarr.open_array(str(out / "campaign.zarr" / "flight_disturbance_rows"), mode="r+")
    rows[0, 0] = ROWS[0, 0] + 1.0
    with pytest.raises(SpecificationError, match=r"flight\.disturbance_file: the store's flight_disturbance_rows"):
        replay(out, 0)


def _bad(tmp_path: Path, flight: str, files: dict[str, np.ndarray], extra: str = "") -> Path:
    for name, array in files.items():
        _csv(tmp_path / name, array)
    return _campaign(tmp_path, flight, extra)


BAD = [
    (
        'disturbance_file = "w.csv"\n',
        {"w.csv": ROWS[:, :2]},
        "",
        DimensionError,
        r"flight\.disturbance_file: .*\(201, 2\)",
    ),
    (
        'disturbance_file = "w.csv"\n',
        {"w.csv": ROWS[:-1]},
        "",
        DimensionError,
        r"flight\.disturbance_file: expected n rows of 3 .*\(201, 3\).*\(200, 3\)",
    ),
    (
        'disturbance_file = "w.csv"\n',
        {"w.csv": np.where(ROWS > 3.0, np.nan, ROWS)},
        "",
        SpecificationError,
        r"flight\.disturbance_file .*w\.csv.* must be finite",
    ),
    (
        'disturbance_file = "missing.csv"\n',
        {},
        "",
        SpecificationError,
        r"flight\.disturbance_file: no file .*missing\.csv",
    ),
    ("disturbance_file = 3\n", {}, "", SpecificationError, r"flight\.disturbance_file must be a file name"),
    (
        'delay_file = "d.csv"\njitter = [0.02, 0.05]\n',
        {"d.csv": DELAYS},
        "",
        SpecificationError,
        r"flight\.jitter and flight\.delay_file",
    ),
    (
        'delay_file = "d.csv"\n',
        {"d.csv": DELAYS[:-1]},
        "",
        DimensionError,
        r"flight\.delay_file: expected n delays .*= 201",
    ),
    (
        'delay_file = "d.csv"\n',
        {"d.csv": DELAYS + 0.01},
        "",
        SpecificationError,
        r"flight\.delay_file \(.*d\.csv\): delays must lie in \[tau_min, tau_max\]",
    ),
    (
        'delay_file = "d.csv"\n',
        {"d.csv": np.where(np.arange(N) == 7, 0.0304, DELAYS)},
        "",
        SpecificationError,
        r"flight\.delay_file: .*whole number",
    ),
    (
        'delay_file = "d.csv"\n',
        {"d.csv": np.where(np.arange(N) == 7, np.nan, DELAYS)},
        "",
        SpecificationError,
        r"flight\.delay_file .* must be finite",
    ),
    (
        'delay_file = "d.csv"\n',
        {"d.csv": DELAYS},
        "[dispersions.tau]\nrange = [0.04, 0.05]\n",
        SpecificationError,
        r"flight\.delay_file fixes tau",
    ),
]


@pytest.mark.parametrize(("flight", "files", "extra", "error", "pattern"), BAD)
def test_bad_files_are_refused_naming_the_key(
    tmp_path: Path, flight: str, files: dict[str, np.ndarray], extra: str, error: type, pattern: str
) -> None:
    with pytest.raises(error, match=pattern):
        load_campaign(_bad(tmp_path, flight, files, extra))


def test_the_predictor_refuses_the_delay_file(tmp_path: Path) -> None:
    _csv(tmp_path / "f.csv", DELAYS)
    path = _campaign(tmp_path, 'delay_file = "f.csv"\n', "[predictor]\n")
    path.write_text(path.read_text().replace('type = "hysteretic"\ndelta = 0.05', 'type = "on-predicted"'))
    with pytest.raises(SpecificationError, match=r"flight\.delay_file does not apply with the predictor"):
        load_campaign(path)


def test_the_predictor_flies_the_disturbance_file(tmp_path: Path) -> None:
    """The predictor takes a per-sample torque (on the plant): the campaign equals an independent
    simulate_batch call with the predictor and the file's rows plus each run's constant torque."""
    from mrpctl import OnPredicted

    _csv(tmp_path / "w.csv", ROWS)
    path = _campaign(tmp_path, 'disturbance = [0.5, 0.0, -0.25]\ndisturbance_file = "w.csv"\n', "[predictor]\n")
    path.write_text(path.read_text().replace('type = "hysteretic"\ndelta = 0.05', 'type = "on-predicted"'))
    spec = load_campaign(path)
    chunk = simulate_chunk(spec, 0, spec.count)
    inputs = run_inputs(spec, 0, spec.count)
    batch = simulate_batch(
        [Spacecraft(J) for J in inputs.inertia],
        inputs.gain_scale[:, None, None] * spec.base.K[None],
        inputs.x0,
        tau=TAU,
        rule=OnPredicted(1.0),
        t_final=T_FINAL,
        rate=RATE,
        threads=1,
        predictor=spec.predictor,
        disturbance=ROWS + np.array([0.5, 0.0, -0.25]),
    )
    for name in METRICS:
        assert np.asarray(getattr(batch, name)).tobytes() == chunk[name].tobytes(), name
    assert (chunk["switch_count"] >= 1).sum() >= 1  # tumbles through 180 deg: switch metrics compared


def test_cli_prints_one_line_and_exits_2_on_a_bad_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _bad(tmp_path, 'disturbance_file = "w.csv"\n', {"w.csv": ROWS[:-3]})
    assert main(["campaign", "run", str(path), "--out", str(tmp_path / "out")]) == USER_ERROR == 2
    one_line_error(capsys, "flight.disturbance_file", "(201, 3)", "(198, 3)")
    assert not (tmp_path / "out").exists()
    path = _bad(tmp_path, 'delay_file = "nowhere.npy"\n', {})
    assert main(["campaign", "run", str(path), "--out", str(tmp_path / "out")]) == 2
    one_line_error(capsys, "flight.delay_file", "nowhere.npy")


@pytest.mark.slow
def test_dask_workers_get_the_numbers_with_the_task(tmp_path: Path) -> None:
    """The files deleted once the campaign is read: a LocalCluster stores what the local runner stores."""
    pytest.importorskip("distributed")
    torque, delays = _csv(tmp_path / "w.csv", ROWS), _csv(tmp_path / "d.csv", DELAYS)
    spec = load_campaign(_campaign(tmp_path, 'disturbance_file = "w.csv"\ndelay_file = "d.csv"\n'))
    torque.unlink()
    delays.unlink()
    run_campaign(spec, tmp_path / "local", chunk=3, threads=1)
    assert run_campaign(spec, tmp_path / "dask", chunk=3, scheduler="local", workers=1).complete
    local, dask = open_campaign(tmp_path / "local"), open_campaign(tmp_path / "dask")
    for name in local.data_vars:
        assert local[name].values.tobytes() == dask[name].values.tobytes(), name
    assert "flight_delays" in dask.data_vars


@pytest.mark.parametrize(
    ("predicted", "file"), [(False, False), (True, False), (False, True)], ids=["hysteretic", "predictor", "file"]
)
def test_runs_differing_only_in_torque_share_one_call_and_equal_simulate(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, predicted: bool, file: bool
) -> None:
    """Runs that differ only in their constant torque w ([dispersions.disturbance], no file) make one
    simulate_batch call with one w per run (before: one call per run, about 9x slower); each run still
    equals simulate of that run alone with its own w, bit for bit (the predictor's runs too: the torque
    acts on the plant, not on its model copy; with a disturbance_file each run flies W_k + w_i)."""
    from mrpctl import OnPredicted
    from mrpctl.campaign import simulation as campaign_simulation

    extra = "[dispersions.disturbance]\nmagnitude = [1.0, 2.0]\n" + ("[predictor]\n" if predicted else "")
    flight = "disturbance = [0.5, 0.0, -0.25]\nu_max = [30.0, 30.0, 30.0]\n"
    if file:
        _csv(tmp_path / "w.csv", ROWS)
        flight += 'disturbance_file = "w.csv"\n'
    path = _campaign(tmp_path, flight, extra)
    if predicted:
        path.write_text(path.read_text().replace(f'type = "hysteretic"\ndelta = {DELTA}', 'type = "on-predicted"'))
    spec = load_campaign(path)
    assert (spec.predictor is not None) == predicted and spec.flight is not None
    calls: list[int] = []
    batch = campaign_simulation._batch

    def counted(spacecraft: list[Spacecraft], *args: Any) -> dict[str, np.ndarray]:
        calls.append(len(spacecraft))
        return batch(spacecraft, *args)

    monkeypatch.setattr(campaign_simulation, "_batch", counted)
    out = simulate_chunk(spec, 0, spec.count)
    assert calls == [6]  # one call for the six runs
    w = out["disturbance"]
    assert len({tuple(row) for row in w.tolist()}) == 6  # six different torques
    inputs = run_inputs(spec, 0, spec.count)
    switched = 0
    for i in range(spec.count):
        alone = simulate(  # each run alone, its torque given as the constant Disturbance it is
            Spacecraft(inputs.inertia[i]),
            inputs.gain_scale[i] * spec.base.K,
            inputs.x0[i],
            tau=TAU,
            rule=OnPredicted(1.0) if predicted else Hysteretic(DELTA),
            t_final=T_FINAL,
            rate=RATE,
            predictor=spec.predictor,
            disturbance=Disturbance(ROWS + w[i] if file else w[i]),
            actuator=spec.flight.actuator,
            keep_every=None,
        )
        switched += alone.switch_count > 0
        assert alone.switch_count == out["switch_count"][i], i
        for name in ("first_switch_time", "max_sigma", "peak_torque", "settling_time"):
            assert np.float64(getattr(alone, name)).tobytes() == np.float64(out[name][i]).tobytes(), (i, name)
    assert switched >= 2  # tumbles through 180 deg: the switch metrics are compared, not only zeros
