"""Published values of the delay-systems toolboxes: DDE-BIFTOOL's neuron demo and PIETOOLS' DDE library.

Every number below was read in the toolbox's own sources (file and commit cited) and is compared at the
precision it is published with. The delays of the neuron (two of 0.2 s and one τ_s) and of PIETOOLS'
example D (τ/2 and τ) make these multi-delay checks.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from mrpctl.design import delay_margin
from mrpctl.design.performance import hinf_bound, hinf_norm
from mrpctl.design.spectra import characteristic_roots, spectral_abscissa

# ------------------------------------------------------------------------------ DDE-BIFTOOL, neuron demo
# DDE-Biftool/DDE-Biftool, demos/neuron/demo1_funcs.m (commit 76060b1c6081bc0c98a69a8b0829d26a658fc9d6):
#   x1' = -κ x1 + β tanh(x1(t − τ_s)) + a12 tanh(x2(t − τ2)),
#   x2' = -κ x2 + β tanh(x2(t − τ_s)) + a21 tanh(x1(t − τ1)),
# parameters [κ, β, a12, a21, τ1, τ2, τ_s] = [1/2, −1, 1, a21, 0.2, 0.2, τ_s]; linearised at (0, 0).
# demos/neuron/html/demo1_hopf.html (same commit) prints the corrected Hopf points
#   parameter: [0.5 -1 1 0.80712 0.2 0.2 1.5], omega: 0.78197      (a21 free)
#   parameter: [0.5 -1 1 0.207 0.2 0.2 8.6341], omega: 0.91575     (τ_s free)
NEURON_HOPF_1 = (0.80712, 0.78197)  # (a21 at τ_s = 1.5, ω)
NEURON_HOPF_2 = (8.6341, 0.91575)  # (τ_s at a21 = 0.207, ω)


def _neuron(a21: float, tau_s: float) -> tuple[np.ndarray, list[np.ndarray], list[float]]:
    kappa, beta, a12 = 0.5, -1.0, 1.0
    delayed = [np.array([[0.0, 0.0], [a21, 0.0]]), np.array([[0.0, a12], [0.0, 0.0]]), beta * np.eye(2)]
    return -kappa * np.eye(2), delayed, [0.2, 0.2, tau_s]


def test_neuron_first_hopf_point_of_dde_biftool() -> None:
    a21 = brentq(lambda a: spectral_abscissa(*_neuron(a, 1.5)), 0.7, 0.9, xtol=1e-12)
    spectrum = characteristic_roots(*_neuron(a21, 1.5), count=4)
    assert spectrum.certified
    assert abs(a21 - NEURON_HOPF_1[0]) <= 0.5e-5
    assert abs(abs(spectrum.rightmost.imag) - NEURON_HOPF_1[1]) <= 0.5e-5
    # the demo's starting point a21 = 2.34 has exactly one unstable mode, and it is real
    start = characteristic_roots(*_neuron(2.34, 1.5), count=4)
    assert start.certified
    unstable = start.roots[start.roots.real > 0]
    assert len(unstable) == 1 and unstable[0].imag == 0.0


def test_neuron_second_hopf_point_of_dde_biftool() -> None:
    # at τ_s ≈ 8.6 another pair is already unstable: follow the root near the published frequency
    def real_part(tau_s: float) -> float:
        spectrum = characteristic_roots(*_neuron(0.207, tau_s), count=8)
        assert spectrum.certified
        return float(spectrum.roots[np.argmin(np.abs(spectrum.roots - 1j * NEURON_HOPF_2[1]))].real)

    tau_s = brentq(real_part, 8.5, 8.8, xtol=1e-12)
    roots = characteristic_roots(*_neuron(0.207, tau_s), count=8).roots
    root = roots[np.argmin(np.abs(roots - 1j * NEURON_HOPF_2[1]))]
    assert abs(tau_s - NEURON_HOPF_2[0]) <= 0.5e-4
    assert abs(root.imag - NEURON_HOPF_2[1]) <= 0.5e-5


# ------------------------------------------------------------------------------ PIETOOLS, DDE library
# CyberneticSCL/PIETOOLS, PIETOOLS/PIETOOLS_examples/examples_DDE_library_PIETOOLS.m
# (commit 1391c2cbeb1353f6e61b14c4b4e2edd020f6c6bd); "answer" lines, with the file's sources:
#   stability, Gu, Kharitonov & Chen (2003) p. 192: A0 = [-2 0; 0 -.9], A1 = [-1 0; -1 -1], "stable range is
#     tau < 6.17258";
#   stability, Peet (2018) example D: A0 = [0 1; -1 .1], A1 = [0 0; -1 0] at τ/2, A2 = [0 0; 1 0] at τ,
#     "tauNmax = 1.3722";
#   stability, Peet (2018) / Egorov & Mondié (2014) example C: x' = -2x + b x(t − 1) − x(t − 2), "bmax = 3";
#   H∞, Egorov & Mondié (2014) example A.1: the p. 192 system, B1 = [-.5; 1], C1 = [1 0], τ = .846: ".2364";
#   H∞, example A.2: A0 = [0 1; -2 .1], A1 = [0 0; 1 0], B1 = I, C1 = [0 1], τ = .846: "2.87";
#   H∞, example D: the example-D system at τ = 1 (delays .5 and 1), B1 = [-.5; 1], C1 = [1 0]: "gamma=4.9784".
# PIETOOLS' numbers come from LMIs: an upper bound on the L2 gain and a certified (lower) delay bound.
GU_A0 = np.array([[-2.0, 0.0], [0.0, -0.9]])
GU_A1 = np.array([[-1.0, 0.0], [-1.0, -1.0]])
PEET_D_A0 = np.array([[0.0, 1.0], [-1.0, 0.1]])
PEET_D_A = [np.array([[0.0, 0.0], [-1.0, 0.0]]), np.array([[0.0, 0.0], [1.0, 0.0]])]


def _sweep(a0: np.ndarray, a: list[np.ndarray], tau: list[float], b: np.ndarray, c: np.ndarray, w: np.ndarray):
    """σ_max(C (iωI − A₀ − Σ Aₖ e^{−iωτₖ})⁻¹ B) on a grid, batched (nothing shared with the module)."""
    n = a0.shape[0]
    m = 1j * w[:, None, None] * np.eye(n) - a0
    for ak, tk in zip(a, tau, strict=True):
        m = m - np.exp(-1j * w * tk)[:, None, None] * ak
    tf = c @ np.linalg.solve(m, np.broadcast_to(b, (len(w), *b.shape)))
    return np.linalg.svd(tf, compute_uv=False)[:, 0]


def test_gu_delay_range_of_the_pietools_library() -> None:
    margin = delay_margin(GU_A0, GU_A1)
    assert abs(margin.margin - 6.17258) <= 0.5e-5
    assert spectral_abscissa(GU_A0, GU_A1, 6.1725) < 0.0 < spectral_abscissa(GU_A0, GU_A1, 6.1727)


def test_two_delay_range_of_the_pietools_library() -> None:
    def abscissa(t: float) -> float:
        return spectral_abscissa(PEET_D_A0, PEET_D_A, [t / 2, t])

    tau_max = brentq(abscissa, 1.3, 1.45, xtol=1e-12)
    # the published figure is a certified lower bound given to four decimals: the true limit is above it
    assert 1.3722 <= tau_max < 1.3723
    # (unstable without delay: the stable range starts near τ = 0.2)
    assert all(abscissa(t) < 0.0 for t in np.linspace(0.3, 1.37, 12))


def test_two_delay_gain_range_of_the_pietools_library() -> None:
    def abscissa(b: float) -> float:
        return spectral_abscissa(-2.0, [b, -1.0], [1.0, 2.0])

    assert brentq(abscissa, 2.9, 3.1, xtol=1e-13) == pytest.approx(3.0, abs=1e-9)
    assert abscissa(2.99) < 0.0 < abscissa(3.01)


@pytest.mark.parametrize(
    ("a0", "a", "tau", "b", "c", "published", "decimals"),
    [
        (GU_A0, [GU_A1], [0.846], np.array([[-0.5], [1.0]]), np.array([[1.0, 0.0]]), 0.2364, 4),
        (
            np.array([[0.0, 1.0], [-2.0, 0.1]]),
            [np.array([[0.0, 0.0], [1.0, 0.0]])],
            [0.846],
            np.eye(2),
            np.array([[0.0, 1.0]]),
            2.87,
            2,
        ),
        (PEET_D_A0, PEET_D_A, [0.5, 1.0], np.array([[-0.5], [1.0]]), np.array([[1.0, 0.0]]), 4.9784, 4),
    ],
    ids=["egorov-mondie-A1", "egorov-mondie-A2", "peet-D-two-delays"],
)
def test_hinf_of_the_pietools_library(a0, a, tau, b, c, published: float, decimals: int) -> None:
    exact = hinf_norm(a0, a, tau, b, c)
    assert exact.finite
    assert abs(exact.value - published) <= 0.5 * 10.0**-decimals
    # and the exact value is the peak of an independent dense sweep
    w = np.linspace(0.0, 10.0, 100_001)
    s = _sweep(a0, a, tau, b, c, w)
    i = int(np.argmax(s))
    fine = np.linspace(w[max(i - 1, 0)], w[i + 1], 20_001)
    peak = max(float(s.max()), float(_sweep(a0, a, tau, b, c, fine).max()))
    assert peak <= exact.value * (1.0 + 1e-9)
    assert peak == pytest.approx(exact.value, rel=1e-6)
    if len(tau) == 1:  # the bounded-real LMI (one delay) bounds it from above, as PIETOOLS' LPI does
        bound = hinf_bound(a0, a[0], tau[0], b, c, order=3)
        assert bound.certified
        assert exact.value <= bound.value <= exact.value * (1.0 + 1e-3)
