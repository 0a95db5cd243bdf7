"""Spectra of delay systems: closed forms (Lambert W), the PD axis, Newton from many starts, literature examples."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import lambertw

from mrpctl import paper
from mrpctl.design import delay_margin, linearized_loop, pd_gains
from mrpctl.design.spectra import (
    characteristic_roots,
    delay_stability_map,
    delay_system,
    plot_spectrum,
    spectral_abscissa,
)
from mrpctl.design.synthesis import pd_rightmost_root
from mrpctl.errors import DimensionError, SpecificationError

# TDS-CONTROL manual, example 2.1 (the system of Verheyden, Luzyanina & Roose 2008, J. Comput. Appl. Math.
# 214; matrices in AppeltansPieter/TDSControl-examples data/VerheydenEtAl2008): one delay tau = 1. Its
# rightmost root 0.6176424667764324 is the value tdcpy's tests (LockeErasmus/tdcpy,
# tests/stability/test_rightmost_root.py) check against TDS-CONTROL.
VERHEYDEN_A0 = np.array([[-1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, -10, -4], [0, 0, 4, -10]])
VERHEYDEN_A1 = np.array([[3.0, 3, 3, 3], [0, -1.5, 0, 0], [0, 0, 3, -5], [0, 5, 5, 5]])
VERHEYDEN_RIGHTMOST = 0.6176424667764324

# Wu & Michiels (2012), "Reliably computing all characteristic roots of delay differential equations in a
# given right half plane using a spectral method", J. Comput. Appl. Math. 236: three delays 0.1, 0.15, 0.25
# (TDS-CONTROL's example set, AppeltansPieter/TDSControl-examples data/WuMichiels2012).
WU_A0 = np.array([[-9.6713, -9.7546, -9.4913], [1.8381, 1.7961, 9.5716], [1.3647, -2.7957, -7.3561]])
WU_A = [
    np.array([[1.0115, -9.3006, 5.3222], [7.2688, -1.1960, 9.9968], [3.6508, -1.2035, -4.8507]]),
    np.array([[7.7163, 4.5911, -5.5072], [-9.0056, -0.0260, -7.5404], [-3.3669, 0.9332, -0.2958]]),
    np.array([[7.4808, -7.2571, 9.4377], [2.8285, -7.1768, -1.4221], [-1.0353, 9.6519, 5.1208]]),
]
WU_TAU = [0.1, 0.15, 0.25]

# Gu, Kharitonov & Chen (2003), Stability of Time-Delay Systems, example: unstable without delay, stable
# exactly for 0.10017 < tau < 1.71785.
GU_A = np.array([[0.0, 1.0], [-2.0, 0.1]])
GU_AD = np.array([[0.0, 0.0], [1.0, 0.0]])


def _lambert_roots(a0: float, a: float, tau: float, branches: int = 6) -> np.ndarray:
    """Roots of s = a0 − a e^{−sτ}: s = a0 + W_k(−aτ e^{−a0τ})/τ over the branches k."""
    z = -a * tau * math.exp(-a0 * tau)
    roots = [a0 + lambertw(z, k) / tau for k in range(-branches, branches + 1)]
    return np.array(sorted(roots, key=lambda s: (-s.real, -s.imag)))


def _independent_newton(system, start: complex, steps: int = 60) -> complex | None:
    """Plain Newton on det M(s) with a central-difference derivative (nothing shared with the module)."""
    s = start
    for _ in range(steps):
        h = 1e-7 * (1.0 + abs(s))
        f = np.linalg.det(system.matrix(s))
        df = (np.linalg.det(system.matrix(s + h)) - np.linalg.det(system.matrix(s - h))) / (2 * h)
        if df == 0 or not np.isfinite(df):
            return None
        step = f / df
        if abs(step) > 2.0 + abs(s):
            return None
        s -= step
        if abs(step) <= 1e-13 * (1.0 + abs(s)):
            break
    sigma = np.linalg.svd(system.matrix(s), compute_uv=False)[-1]
    return s if sigma <= 1e-9 * (abs(s) + system.norm_sum) else None


@pytest.mark.parametrize(("a0", "a", "tau"), [(0.0, 1.0, 1.0), (0.0, 2.0, 0.7), (-0.5, 1.3, 2.0), (0.3, -0.2, 1.5)])
def test_scalar_roots_are_the_lambert_w_branches(a0: float, a: float, tau: float) -> None:
    spectrum = characteristic_roots(a0, -a, tau, count=7)
    expected = _lambert_roots(a0, a, tau)
    assert spectrum.certified
    for s in spectrum.roots:
        assert np.min(np.abs(expected - s)) <= 1e-10 * (1.0 + abs(s))
    # and nothing between: the listed roots are the rightmost Lambert branches
    assert np.allclose(spectrum.roots[:4], expected[:4], rtol=1e-10, atol=1e-12)


def test_two_delays_decoupled_give_the_union_of_the_lambert_roots() -> None:
    a1 = np.diag([-1.0, 0.0])
    a2 = np.diag([0.0, -0.8])
    spectrum = characteristic_roots(np.zeros((2, 2)), [a1, a2], [1.0, 2.5], count=8)
    expected = np.concatenate([_lambert_roots(0.0, 1.0, 1.0), _lambert_roots(0.0, 0.8, 2.5)])
    assert spectrum.certified
    for s in spectrum.roots:
        assert np.min(np.abs(expected - s)) <= 1e-10 * (1.0 + abs(s))
    best = sorted(expected, key=lambda s: -s.real)[0]
    assert spectrum.abscissa == pytest.approx(best.real, rel=1e-10)


@pytest.mark.parametrize(("w", "zeta"), [(0.2, 1.0), (0.444854, 1.0), (0.281287, 0.81973), (0.6, 0.5), (1.2, 2.0)])
def test_pd_axis_matches_pd_rightmost_root(w: float, zeta: float) -> None:
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    a_d = np.array([[0.0, 0.0], [-w * w, -2.0 * zeta * w]])
    spectrum = characteristic_roots(a, a_d, 1.0, count=4)
    assert spectrum.certified
    assert spectrum.abscissa == pytest.approx(pd_rightmost_root(w, zeta).real, rel=1e-9, abs=1e-12)


def test_identical_axes_give_triple_roots_counted_three_times() -> None:
    gains = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=0.889707)
    loop = linearized_loop(paper.SPACECRAFT, gains.K)
    spectrum = characteristic_roots(loop.A, loop.A_d, 0.5, count=3)
    assert spectrum.certified
    assert spectrum.multiplicities[0] == 3
    assert spectrum.abscissa == pytest.approx(pd_rightmost_root(0.889707 * 0.5, 1.0).real / 0.5, rel=1e-9)


def test_tds_control_manual_example_rightmost_root() -> None:
    spectrum = characteristic_roots(VERHEYDEN_A0, VERHEYDEN_A1, 1.0, count=8)
    assert spectrum.certified
    assert spectrum.rightmost.imag == 0.0
    assert spectrum.abscissa == pytest.approx(VERHEYDEN_RIGHTMOST, rel=1e-12)


@pytest.mark.parametrize(
    ("a0", "a", "tau"),
    [(VERHEYDEN_A0, [VERHEYDEN_A1], [1.0]), (WU_A0, WU_A, WU_TAU), (GU_A, [GU_AD], [1.0])],
    ids=["verheyden2008", "wu-michiels2012-three-delays", "gu2003"],
)
def test_newton_from_many_starts_finds_no_root_that_is_not_listed(a0, a, tau) -> None:
    spectrum = characteristic_roots(a0, a, tau, count=8)
    assert spectrum.certified
    system = delay_system(a0, a, tau)
    rng = np.random.default_rng(7)
    top = float(np.max(np.abs(spectrum.roots.imag))) + 2.0
    found = 0
    for _ in range(300):
        start = complex(rng.uniform(spectrum.count_line, spectrum.abscissa + 2.0), rng.uniform(-top, top))
        root = _independent_newton(system, start)
        if root is None or root.real <= spectrum.count_line + 1e-9:
            continue
        found += 1
        assert np.min(np.abs(spectrum.roots - root)) <= 1e-7 * (1.0 + abs(root)), root
    assert found >= 30


def test_three_delay_example_is_independent_of_the_discretisation() -> None:
    coarse = characteristic_roots(WU_A0, WU_A, WU_TAU, count=6)
    fine = characteristic_roots(WU_A0, WU_A, WU_TAU, count=6, nodes=100)
    assert coarse.certified and fine.certified
    assert np.allclose(coarse.roots, fine.roots, rtol=1e-11, atol=1e-11)
    assert coarse.abscissa < 0.0  # the example is stable


def test_paper_loop_at_its_exact_margin_has_a_root_on_the_axis() -> None:
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    margin = delay_margin(loop.A, loop.A_d)
    crossing = margin.crossings[0]
    spectrum = characteristic_roots(loop.A, loop.A_d, margin.margin, count=4)
    assert abs(spectrum.abscissa) <= 1e-9
    assert spectrum.rightmost.imag == pytest.approx(crossing.frequency, rel=1e-9)
    assert spectral_abscissa(loop.A, loop.A_d, 0.5) < 0.0 < spectral_abscissa(loop.A, loop.A_d, 1.01 * margin.margin)


def test_every_stable_interval_is_found_and_agrees_with_the_spectrum() -> None:
    # undamped oscillator with delayed damping: damping, anti-damping and damping again as tau grows
    stability = delay_stability_map([[0.0, 1.0], [-1.0, 0.0]], [[0.0, 0.0], [0.0, -0.5]])
    assert len(stability.stable_intervals) >= 2
    assert stability.consistent
    gu = delay_stability_map(GU_A, GU_AD)
    assert len(gu.stable_intervals) == 1
    lo, hi = gu.stable_intervals[0]
    assert lo == pytest.approx(0.10017, abs=1e-5) and hi == pytest.approx(1.71785, abs=1e-5)
    assert gu.consistent


def test_delay_free_system_is_the_matrix_spectrum() -> None:
    a = np.array([[-1.0, 2.0], [0.0, -3.0]])
    spectrum = characteristic_roots(a, a, 0.0)
    assert np.allclose(np.sort(spectrum.roots.real), np.sort(np.linalg.eigvals(2 * a).real))
    assert spectrum.certified


def test_bad_input_is_refused_naming_the_parameter() -> None:
    with pytest.raises(SpecificationError, match="A0"):
        characteristic_roots([[math.nan]], [[1.0]], 1.0)
    with pytest.raises(SpecificationError, match=r"A\[0\]"):
        characteristic_roots([[0.0]], [[math.inf]], 1.0)
    with pytest.raises(DimensionError, match=r"A\[1\]"):
        characteristic_roots(np.eye(2), [np.eye(2), np.eye(3)], [1.0, 2.0])
    with pytest.raises(DimensionError, match="tau"):
        characteristic_roots(np.eye(2), [np.eye(2), np.eye(2)], [1.0])
    with pytest.raises(SpecificationError, match=r"tau\[0\]"):
        characteristic_roots(0.0, -1.0, -0.5)
    with pytest.raises(SpecificationError, match=r"tau\[0\]"):
        characteristic_roots(0.0, -1.0, math.nan)
    with pytest.raises(SpecificationError, match="count"):
        characteristic_roots(0.0, -1.0, 1.0, count=0)


def test_plot_draws_every_root() -> None:
    spectrum = characteristic_roots(VERHEYDEN_A0, VERHEYDEN_A1, 1.0, count=5)
    figure = plot_spectrum(spectrum)
    (axes,) = figure.axes
    xs = np.concatenate([line.get_xdata() for line in axes.get_lines() if line.get_marker() == "x"])
    assert len(xs) == len(spectrum.roots)
