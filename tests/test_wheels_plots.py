"""The wheel figure: speeds and torques of every wheel with their limits."""

from __future__ import annotations

import numpy as np
import pytest

from mrpctl import WheelCluster, simulate
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.model import gain_from_pd, state
from mrpctl.plots import plot_wheels, save_figure
from mrpctl.spacecraft import Spacecraft

CRAFT = Spacecraft(np.diag([0.2, 0.25, 0.15]))


def test_plot_wheels_draws_every_wheel_and_its_limits(tmp_path) -> None:
    wheels = WheelCluster.pyramid(1e-4, [4e-3, 5e-3, 6e-3, 5e-3], 300.0)
    K = gain_from_pd(CRAFT, -0.04 * np.ones(3), -0.4 * np.ones(3))
    run = simulate(
        CRAFT, K, state([0.5, -0.3, 0.2], [0.02, 0.0, -0.01]), tau=0.2, rule=Hysteretic(0.1), t_final=30.0,
        rate=10.0, wheels=wheels,
    )  # fmt: skip
    fig = plot_wheels(run)
    speeds_ax, torque_ax = fig.axes[:2]
    drawn = [line for line in speeds_ax.get_lines() if len(line.get_xdata()) == run.t.size]
    assert len(drawn) == 4
    rpm = 60.0 / (2.0 * np.pi)
    levels = {round(float(line.get_ydata()[0]), 9) for line in speeds_ax.get_lines() if len(line.get_xdata()) == 2}
    assert {round(300.0 * rpm, 9), round(-300.0 * rpm, 9)} <= levels
    torque_levels = {float(line.get_ydata()[0]) for line in torque_ax.get_lines() if len(line.get_xdata()) == 2}
    assert {4e-3, -4e-3, 6e-3, -6e-3} <= torque_levels
    assert np.array_equal(drawn[0].get_ydata(), run.wheels.speeds[:, 0] * rpm)
    path = save_figure(fig, tmp_path / "wheels.png")
    assert path.stat().st_size > 1000


def test_plot_wheels_refuses_a_run_without_wheels() -> None:
    K = gain_from_pd(CRAFT, -0.04 * np.ones(3), -0.4 * np.ones(3))
    run = simulate(
        CRAFT, K, state([0.1, 0.0, 0.0], [0.0, 0.0, 0.0]), tau=0.2, rule=Hysteretic(0.1), t_final=1.0, rate=10.0
    )
    with pytest.raises(SpecificationError, match="wheel cluster"):
        plot_wheels(run)
