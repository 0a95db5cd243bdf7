"""Figures compared as images against committed baselines (pytest-mpl; run with ``--mpl``).

Without ``--mpl`` the tests only build the figures. The baselines in ``tests/baseline`` are
rendered by Agg at 40 dpi with matplotlib's default style and its bundled DejaVu fonts;
regenerate them after a deliberate figure change with
``pytest --mpl-generate-path=tests/baseline tests/test_figures_images.py`` and look at them.
The tolerance (RMS of the pixel difference, 0-255) allows for anti-aliasing differences
between FreeType builds; a moved line, a changed label or axis range exceeds it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from mrpctl import paper, plots, simulate
from mrpctl.flight import ActuatorModel
from mrpctl.scenario import load_scenario
from mrpctl.switching import OnCurrent, OnDelayed

pytest.importorskip("pytest_mpl")

COMPARE = dict(baseline_dir="baseline", tolerance=3, style="default", savefig_kwargs={"dpi": 40})


@pytest.fixture(scope="module")
def delayed_run():
    """The paper's case over 2 s with OnDelayed: |σ| crosses 1, the rule switches from 0.944 s."""
    return simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=paper.TAU, rule=OnDelayed(), t_final=2.0)


@pytest.mark.mpl_image_compare(filename="response_delayed.png", **COMPARE)
def test_response_image(delayed_run) -> Figure:
    return plots.plot_response(delayed_run, u_max=ActuatorModel(u_max=[90.0, 50.0, 40.0]))


@pytest.mark.mpl_image_compare(filename="response_small_angle.png", **COMPARE)
def test_small_angle_response_image() -> Figure:
    run = simulate(
        paper.SPACECRAFT, paper.GAIN, np.asarray(paper.INITIAL_STATE) * 0.1, tau=0.0, rule=OnCurrent(), t_final=10.0
    )
    return plots.plot_response(run)  # the σ axis fits |σ| <= 0.093, no |σ| = 1 line


@pytest.mark.mpl_image_compare(filename="attitude_zoom.png", **COMPARE)
def test_attitude_zoom_image(delayed_run) -> Figure:
    return plots.plot_attitude(delayed_run, window=(0.9, 1.0))


@pytest.mark.mpl_image_compare(filename="sweep_eps.png", **COMPARE)
def test_sweep_image() -> Figure:
    return plots.plot_sweep(
        [0.001, 0.005, 0.05, 0.2],
        switch_count=[26, 114, 901, 1881],
        settling_time=[np.nan, 51.2, 59.2, 54.5],
        converged=[False, True, True, True],
        max_sigma=[7.07, 1.02, 1.05, 1.1],
        parameter_label="boundary layer thickness eps (-)",
    )


@pytest.mark.mpl_image_compare(filename="noise_study.png", **COMPARE)
def test_noise_study_image() -> Figure:
    return plots.plot_noise_study(
        [0.0, 0.01],
        [1.0, 1.1],
        switch_count=[[0, 3], [250, 4]],
        settling_time=[[50.0, 52.0], [np.nan, 53.5]],
        title="controller-side rule under attitude noise",
    )


@pytest.mark.mpl_image_compare(filename="pointing_nadir.png", **COMPARE)
def test_pointing_image() -> Figure:
    """The shipped nadir-pointing scenario: Φ_B/R from 20° down past the 0.05° band, slew time and settling."""
    scenario = load_scenario(Path(__file__).resolve().parents[1] / "examples" / "scenarios" / "nadir.toml")
    return plots.plot_pointing(scenario.simulate())
