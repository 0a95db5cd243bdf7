"""The estimation figures: the error with its ±3σ envelope, the NEES with its χ² band."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from mrpctl.errors import DimensionError
from mrpctl.plots import plot_estimation_error, plot_nees, render_rgba

ARCSEC = np.pi / (180 * 3600)


def test_estimation_error_figure_draws_the_error_inside_its_envelope():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 10, 201)
    sigma = np.full((201, 3), 5 * ARCSEC)
    error = rng.normal(0, 5 * ARCSEC, (201, 3))
    fig = plot_estimation_error(t, error, sigma, title="MEKF, tau = 0.5 s")
    axes = fig.axes[:3]
    for axis, a in enumerate(axes):
        line = a.get_lines()[0]
        assert np.allclose(line.get_ydata(), error[:, axis] / ARCSEC)
        envelope = a.collections[0].get_paths()[0].vertices[:, 1]
        assert np.isclose(envelope.max(), 15.0) and np.isclose(envelope.min(), -15.0)
        share = np.mean(np.abs(error[:, axis]) <= 3 * sigma[:, axis])
        assert f"{share:.1%}" in a.get_title(loc="right")
    assert "τ" in fig.get_suptitle()
    assert render_rgba(fig).shape[2] == 4
    with pytest.raises(DimensionError, match="sigma"):
        plot_estimation_error(t, error, sigma[:10])


def test_nees_figure_band_is_the_chi_square_interval_over_the_runs():
    rng = np.random.default_rng(1)
    runs, n = 100, 50
    nees = rng.chisquare(6, (runs, n))
    fig = plot_nees(np.arange(n) * 0.1, nees, dimension=6)
    a = fig.axes[0]
    band = a.patches[0]  # the axhspan rectangle, its y in data units
    low, high = chi2.ppf([0.025, 0.975], runs * 6) / runs
    assert np.isclose(band.get_y(), low) and np.isclose(band.get_y() + band.get_height(), high)
    assert np.allclose(a.get_lines()[-1].get_ydata(), nees.mean(axis=0))
    with pytest.raises(DimensionError):
        plot_nees(np.arange(n), nees[:, :10], dimension=6)
