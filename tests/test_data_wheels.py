"""A run on wheels saved and loaded (mrpctl.data): its wheel speeds, torques, metrics and cluster come back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from mrpctl import simulate
from mrpctl.data import load, save
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.model import state
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

RPM = 2.0 * np.pi / 60.0


@pytest.fixture(scope="module")
def run():
    # a pyramid with friction, null-space management toward a bias and the gyroscopic term: every cluster field
    wheels = WheelCluster.pyramid(
        [3.0e-5, 3.1e-5, 3.2e-5, 3.3e-5],
        5e-3,
        6000.0 * RPM,
        viscous=1e-7,
        coulomb=2e-6,
        speeds=[10.0, -10.0, 5.0, 0.0],
        null_gain=0.05,
        bias_speeds=[50.0, -50.0, 50.0, -50.0],
        gyroscopic=True,
    )
    sc = Spacecraft([0.2, 0.25, 0.15])
    K = np.hstack((-np.diag([3.958, 4.947, 2.968]), -4.0 * np.diag([0.8897, 1.1121, 0.6673])))
    x0 = state([0.1, -0.2, 0.05], [0.0, 0.01, 0.0])
    return simulate(sc, K, x0, tau=0.2, rule=Hysteretic(0.1), t_final=20.0, rate=50.0, wheels=wheels)


def test_a_run_on_wheels_comes_back(run, tmp_path: Path) -> None:
    back = load(save(run, tmp_path / "run.nc"))
    assert back.wheels is not None and run.wheels is not None
    assert back.wheels.cluster.key() == run.wheels.cluster.key()
    assert np.array_equal(back.wheels.cluster.speeds, run.wheels.cluster.speeds)
    for name in ("speeds", "motor_torque", "final_speeds", "peak_speed", "torque_limited_time", "speed_limited_time"):
        assert np.asarray(getattr(back.wheels, name)).tobytes() == np.asarray(getattr(run.wheels, name)).tobytes()
    assert back.wheels.peak_momentum == run.wheels.peak_momentum and back.wheels.worst_wheel == run.wheels.worst_wheel
    assert np.array_equal(back.u, run.u) and back.saturated_fraction == run.saturated_fraction
    # the file's own numbers: the speeds over (time, wheel), the axes over (axis, wheel)
    with xr.open_dataset(tmp_path / "run.nc") as saved:
        assert saved["wheel_speed"].dims == ("time", "wheel") and saved["wheel_speed"].shape == (1001, 4)
        assert np.array_equal(saved["wheel_spin_axes"].values, run.wheels.cluster.spin_axes)
        assert saved["wheel_speed_limit"].attrs["units"] == "rad/s"


def test_a_run_without_wheels_has_no_wheel_variables(tmp_path: Path) -> None:
    plain = simulate(
        Spacecraft([0.2, 0.25, 0.15]), -np.eye(3, 6), np.zeros(6), tau=0.0, rule=Hysteretic(0.1), t_final=1.0
    )
    with xr.open_dataset(save(plain, tmp_path / "plain.nc")) as saved:
        assert not [name for name in saved.variables if str(name).startswith("wheel")]
    assert load(tmp_path / "plain.nc").wheels is None


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        (lambda d: d.drop_vars("wheel_peak_speed"), "wheel_peak_speed is missing"),
        (lambda d: d.assign(wheel_spin_inertia=d["wheel_spin_inertia"] * 0.0), "spin_inertia must be > 0"),
    ],
    ids=["a-variable-missing", "a-bad-cluster"],
)
def test_a_damaged_run_on_wheels_is_refused(run, tmp_path: Path, change, needle: str) -> None:
    path = save(run, tmp_path / "run.nc")
    with xr.open_dataset(path) as saved:
        damaged = change(saved.load())
    damaged.to_netcdf(tmp_path / "damaged.nc", engine="scipy", format="NETCDF3_64BIT")
    with pytest.raises(SpecificationError, match=needle):
        load(tmp_path / "damaged.nc")
