"""mrpctl.data: labelled conversions, save/load round trip (atomic), decimating CSV."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

from mrpctl import BoundaryLayer, DelayAware, data, paper, simulate, simulate_batch
from mrpctl.errors import SpecificationError

X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])


def _run(rule=None, t_final: float = 4.0, rate: float = 100.0, tau: float = 0.5):
    return simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        X0,
        tau=tau,
        rule=rule or DelayAware(),
        t_final=t_final,
        rate=rate,
    )


@pytest.fixture(scope="module")
def run():
    return _run(BoundaryLayer(eps=0.2))


def test_run_to_xarray_and_pandas_are_labelled(run):
    ds = data.to_xarray(run)
    assert ds.sizes == {
        "time": len(run.t),
        "axis": 3,
        "row": 3,
        "col": 3,
        "input": 3,
        "state": 6,
        "switch": run.switch_count,
    }
    assert np.array_equal(ds["time"].values, run.t) and ds["time"].attrs["units"] == "s"
    assert np.array_equal(ds["sigma"].sel(axis=2).values, run.sigma[:, 1])
    assert np.array_equal(ds["u"].values, run.u)
    assert np.array_equal(np.flatnonzero(ds["switched"].values), run.switch_indices)
    assert float(ds["tau"]) == run.tau and np.array_equal(ds["K"].values, run.K)
    frame = data.to_pandas(run)
    assert frame.index.name == "t" and list(frame.columns[:3]) == ["sigma1", "sigma2", "sigma3"]
    assert np.array_equal(frame["omega3"].to_numpy(), run.omega[:, 2])
    assert frame.attrs["rule"] == str(run.rule)


def test_batch_to_xarray_and_pandas_have_inputs_per_run():
    x0 = np.array([X0, [0.5, 0.1, 0.0, 0.0, 0.02, 0.0]])
    batch = simulate_batch(
        paper.SPACECRAFT, paper.GAIN, x0, tau=[0.5, 0.3], rule=DelayAware(), t_final=2.0, rate=100.0, threads=1
    )
    ds = data.to_xarray(batch)
    assert ds.sizes["run"] == 2
    assert np.array_equal(ds["omega0"].values, 4.0 * x0[:, 3:])
    assert np.array_equal(ds["tau"].values, [0.5, 0.3])
    assert np.array_equal(ds["switch_count"].values, batch.switch_count)
    frame = data.to_pandas(batch)
    assert frame.index.name == "run" and frame.loc[1, "sigma0_1"] == 0.5 and frame.loc[1, "omega0_2"] == 0.08
    assert list(frame["converged"]) == list(batch.converged)


def test_save_load_round_trip(run, tmp_path):
    path = data.save(run, tmp_path / "run.nc", seed=42)
    back = data.load(path)
    for name in ("t", "sigma", "omega", "u", "switch_indices", "switch_times", "sign_flips", "K", "x0"):
        assert np.array_equal(getattr(back, name), getattr(run, name)), name
    for name in (
        "max_sigma",
        "settling_time",
        "diverged",
        "tau",
        "rate",
        "delay_samples",
        "substeps",
        "t_final",
        "history",
        "switch_count",
        "first_switch_time",
        "last_switch_time",
        "peak_torque",
        "samples",
        "keep_every",
    ):
        assert getattr(back, name) == getattr(run, name), name
    assert back.rule == run.rule and back.spacecraft == run.spacecraft
    assert not back.sigma.flags.writeable
    meta = data.metadata(path)
    assert meta["seed"] == 42 and "casadi" in meta["versions"]
    assert not list(tmp_path.glob("*.tmp"))


def test_save_is_atomic_when_interrupted(run, tmp_path, monkeypatch):
    """A save that fails mid-write leaves the old file intact and no temporary file behind."""
    path = data.save(_run(t_final=1.0), tmp_path / "run.nc")
    before = path.read_bytes()
    import xarray as xr

    def interrupted(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(xr.Dataset, "to_netcdf", interrupted)
    with pytest.raises(KeyboardInterrupt):
        data.save(run, path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.nc"]


def test_load_refuses_foreign_files(tmp_path):
    with pytest.raises(SpecificationError, match="no saved run"):
        data.load(tmp_path / "missing.nc")
    import xarray as xr

    xr.Dataset({"a": ("x", [1.0])}).to_netcdf(tmp_path / "other.nc", engine="scipy")
    with pytest.raises(SpecificationError, match="not a run saved"):
        data.load(tmp_path / "other.nc")


@pytest.mark.slow
def test_csv_of_a_one_hour_run_at_1khz_decimated(tmp_path):
    """3.6e6 samples written every 1000th: 3 601 rows plus the header, values exact, switches all counted."""
    long = _run(DelayAware(), t_final=3600.0, rate=1000.0)
    assert len(long.t) == 3_600_001
    path = data.write_csv(long, tmp_path / "long.csv", every=1000)
    frame = pd.read_csv(path)
    assert len(frame) == 3601
    assert np.array_equal(frame["t"].to_numpy(), long.t[::1000])
    assert np.array_equal(frame["sigma1"].to_numpy(), long.sigma[::1000, 0])  # shortest round-trip repr
    assert np.array_equal(frame["u3"].to_numpy(), long.u[::1000, 2])
    assert int(frame["switches"].sum()) == long.switch_count
    assert path.stat().st_size < 2_000_000
    # 72 001 rows: more than one formatting block of write_csv, still exact and in order
    frame = pd.read_csv(data.write_csv(long, tmp_path / "long50.csv", every=50))
    assert len(frame) == 72001
    assert np.array_equal(frame["t"].to_numpy(), long.t[::50])
    assert np.array_equal(frame["omega2"].to_numpy(), long.omega[::50, 1])
    assert int(frame["switches"].sum()) == long.switch_count


def test_csv_decimation_keeps_last_sample_and_counts_switches(run, tmp_path):
    frame = pd.read_csv(data.write_csv(run, tmp_path / "r.csv", every=7))
    n = len(run.t)
    rows = list(range(0, n, 7)) + ([n - 1] if (n - 1) % 7 else [])
    assert np.array_equal(frame["t"].to_numpy(), run.t[rows])
    switched = np.zeros(n, dtype=int)
    switched[run.switch_indices] = 1
    expected = [switched[: rows[0] + 1].sum()] + [switched[a + 1 : b + 1].sum() for a, b in itertools.pairwise(rows)]
    assert frame["switches"].tolist() == expected
    with pytest.raises(SpecificationError, match="every"):
        data.write_csv(run, tmp_path / "bad.csv", every=0)


def test_result_methods_are_the_data_functions():
    run = _run(t_final=1.0)
    assert run.to_xarray().equals(data.to_xarray(run))
    assert run.to_pandas().equals(data.to_pandas(run))
    batch = simulate_batch(
        paper.SPACECRAFT, paper.GAIN, np.stack([X0, 0.5 * X0]), tau=0.5, rule=DelayAware(), t_final=1.0, rate=100.0
    )
    assert batch.to_xarray().equals(data.to_xarray(batch))
    assert batch.to_pandas().equals(data.to_pandas(batch))


def test_decimated_run_round_trip(tmp_path):
    """A run kept every 7th sample saves and loads with its exact switch list and metrics."""
    run = simulate(paper.SPACECRAFT, paper.GAIN, X0, tau=0.5, rule=BoundaryLayer(0.005), t_final=3.0, keep_every=7)
    assert run.switch_count > 0 and run.keep_every == 7
    back = data.load(data.save(run, tmp_path / "run.nc"))
    for name in ("t", "sigma", "switch_indices", "switch_times"):
        assert np.array_equal(getattr(back, name), getattr(run, name)), name
    for name in ("switch_count", "first_switch_time", "last_switch_time", "peak_torque", "samples", "keep_every"):
        assert getattr(back, name) == getattr(run, name), name
