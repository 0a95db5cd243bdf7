"""Figures: the right data on the right axes, labels with units, switch markers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mrpctl import paper, plots, simulate
from mrpctl.switching import BoundaryLayer


@pytest.fixture(scope="module")
def result():
    return simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        paper.INITIAL_STATE,
        tau=paper.TAU,
        rule=BoundaryLayer(eps=paper.BOUNDARY_LAYER_EPS),
        t_final=5.0,
    )


def test_response_figure_carries_the_run(result, tmp_path: Path) -> None:
    fig = plots.plot_response(result)
    sigma_ax, omega_ax, u_ax = fig.axes
    assert "σ" in sigma_ax.get_ylabel() and "rad/s" in omega_ax.get_ylabel() and "N m" in u_ax.get_ylabel()
    assert u_ax.get_xlabel() == "time t (s)"
    sigma1 = sigma_ax.lines[0]
    assert np.array_equal(sigma1.get_xdata(), result.t)
    assert np.array_equal(sigma1.get_ydata(), result.sigma[:, 0])
    assert np.array_equal(u_ax.lines[0].get_ydata(), result.u[:, 0])
    markers = [line for line in sigma_ax.lines if line.get_label() == "switch"]
    assert len(markers) == 1 and np.array_equal(markers[0].get_xdata(), result.switch_times)
    assert str(result.switch_count) in sigma_ax.get_title()
    path = plots.save_figure(fig, tmp_path / "sub" / "response.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_attitude_window(result) -> None:
    fig = plots.plot_attitude(result, window=(0.9, 1.2))
    (ax,) = fig.axes
    times = ax.lines[0].get_xdata()
    assert times.min() >= 0.9 and times.max() <= 1.2
    switches = next(line for line in ax.lines if line.get_label() == "switch").get_xdata()
    expected = result.switch_times[(result.switch_times >= 0.9) & (result.switch_times <= 1.2)]
    assert np.array_equal(switches, expected) and len(expected) > 0
    assert ax.get_xlim() == (0.9, 1.2)


def test_sweep_figure_sorts_by_parameter() -> None:
    fig = plots.plot_sweep(
        [0.2, 0.001, 0.05],
        switch_count=[30, 2, 10],
        settling_time=[50.0, np.nan, 40.0],
        converged=[True, False, True],
        parameter_label="eps (-)",
    )
    count_ax, settle_ax, converged_ax = fig.axes
    assert list(count_ax.lines[0].get_xdata()) == [0.001, 0.05, 0.2]
    assert list(count_ax.lines[0].get_ydata()) == [2, 10, 30]
    assert np.isnan(settle_ax.lines[0].get_ydata()[0]) and settle_ax.get_ylabel() == "settling time (s)"
    assert converged_ax.get_xscale() == "log"
    assert converged_ax.get_xlabel() == "eps (-)"
