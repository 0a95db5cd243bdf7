"""H₂ and H∞ of the sampled loop (ZOH, d samples of delay) against independently written references."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import scipy.linalg

from mrpctl import paper
from mrpctl.design.performance import hinf_norm
from mrpctl.design.pointing import h2_norm, torque_to_attitude
from mrpctl.design.sampled_performance import sampled_h2_norm, sampled_hinf_norm, sampled_l2_gain
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import gain_matrix

AXIS_A = np.array([[0.0, 1.0], [0.0, 0.0]])
AXIS_B = np.array([[0.0], [1.0]])
AXIS_K = np.array([[-1.0, -1.4]])
AXIS_C = np.array([[1.0, 0.0]])

RNG_A = np.array([[-0.3, 1.0, 0.2], [-0.5, -0.4, 0.0], [0.1, 0.3, -0.8]])
RNG_B = np.array([[0.0, 0.4], [1.0, 0.0], [0.2, 1.0]])
RNG_K = np.array([[-0.4, -0.6, 0.1], [0.2, -0.1, -0.5]])
RNG_BW = np.array([[1.0], [0.3], [-0.5]])
RNG_C = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.0]])


def _expm_pair(a: np.ndarray, b: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """(e^{Ar}, ∫₀ʳ e^{As} ds b) by the augmented exponential (written here, not imported)."""
    n, m = a.shape[0], b.shape[1]
    aug = np.zeros((n + m, n + m))
    aug[:n, :n], aug[:n, n:] = a, b
    e = scipy.linalg.expm(aug * r)
    return e[:n, :n], e[:n, n:]


def _impulse_h2(a, b, k, h, d, bw, c, nodes: int = 24, periods: int = 4000) -> float:
    """Chen & Francis' H₂ of the periodic loop: impulse responses' output energy averaged over the impulse time.

    For w = e_j δ(t − s), s ∈ (0, h): x(t) = e^{A(t−s)} B_w e_j until the next sample (the command line is
    empty); afterwards x(t_k + r) = e^{Ar} x_k + Γ(r) K x_{k−d}. Output energy per period and the average
    over s by Gauss–Legendre quadrature; x_k kept as a plain history list.
    """
    gl_x, gl_w = np.polynomial.legendre.leggauss(nodes)
    r_nodes, r_weights = 0.5 * h * (gl_x + 1.0), 0.5 * h * gl_w
    pairs = [_expm_pair(a, b, r) for r in r_nodes]
    phi, gam = _expm_pair(a, b, h)
    total = 0.0
    for s, ws in zip(r_nodes, r_weights, strict=True):
        for j in range(bw.shape[1]):
            x0 = bw[:, j]
            # the part of the first period after the impulse: ∫₀^{h−s} |C e^{Ar} x0|² dr
            sub_x, sub_w = 0.5 * (h - s) * (gl_x + 1.0), 0.5 * (h - s) * gl_w
            energy = sum(
                wr * float(np.sum((c @ scipy.linalg.expm(a * r) @ x0) ** 2)) for r, wr in zip(sub_x, sub_w, strict=True)
            )
            history = [np.zeros(a.shape[0])] * (d + 1)  # x_{k−d} … x_k before the impulse: all zero
            x = scipy.linalg.expm(a * (h - s)) @ x0
            for _ in range(periods):
                history = [*history[1:], x]
                u = k @ history[0]
                part = sum(
                    wr * float(np.sum((c @ (e @ x + g @ u)) ** 2)) for (e, g), wr in zip(pairs, r_weights, strict=True)
                )
                energy += part
                x = phi @ x + gam @ u
                if part < 1e-18 * energy and np.linalg.norm(np.concatenate(history)) < 1e-12:
                    break
            total += ws * energy
    return math.sqrt(total / h)


@pytest.mark.parametrize(
    ("a", "b", "k", "h", "d", "bw", "c"),
    [
        (AXIS_A, AXIS_B, AXIS_K, 0.1, 3, AXIS_B, AXIS_C),
        (AXIS_A, AXIS_B, AXIS_K, 0.25, 0, AXIS_B, AXIS_C),
        (RNG_A, RNG_B, RNG_K, 0.2, 2, RNG_BW, RNG_C),
    ],
    ids=["axis-d3", "axis-d0", "coupled-3-state"],
)
def test_sampled_h2_matches_the_averaged_impulse_energy(a, b, k, h, d, bw, c) -> None:
    result = sampled_h2_norm(a, b, k, h, delay_samples=d, B_w=bw, C=c)
    assert result.finite
    assert result.value == pytest.approx(_impulse_h2(a, b, k, h, d, bw, c), rel=1e-7)


def test_sampled_h2_and_hinf_tend_to_the_continuous_delayed_loop() -> None:
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    k = gain_matrix(paper.GAIN)
    h2 = h2_norm(a, a_d, 0.5, b, c).value
    hinf = hinf_norm(a, [a_d], [0.5], b, c).value
    err2, errinf = [], []
    for d in (10, 20, 40):
        err2.append(abs(sampled_h2_norm(a, b, k, 0.5 / d, delay_samples=d, C=c).value - h2) / h2)
        errinf.append(abs(sampled_hinf_norm(a, b, k, 0.5 / d, delay_samples=d, C=c).value - hinf) / hinf)
    # first order in h: each halving of the period halves the gap (to 15 %)
    for err in (err2, errinf):
        assert err[-1] < 5e-3
        for coarse, fine in itertools.pairwise(err):
            assert 0.425 <= fine / coarse <= 0.575


def _discrete_sweep(a, b, k, h, d, bw, c, theta: np.ndarray) -> np.ndarray:
    """σ_max(C (zI − Φ − z^{−d} Γ K)⁻¹ Γ_w) at z = e^{iθ}: the transfer function without any state augmentation."""
    phi, gam = _expm_pair(a, b, h)
    _, gam_w = _expm_pair(a, bw, h)
    z = np.exp(1j * theta)
    n = a.shape[0]
    m = z[:, None, None] * np.eye(n) - phi - (z ** (-d))[:, None, None] * (gam @ k)
    tf = c @ np.linalg.solve(m, np.broadcast_to(gam_w, (len(theta), *gam_w.shape)))
    return np.linalg.svd(tf, compute_uv=False)[:, 0]


@pytest.mark.parametrize(
    ("a", "b", "k", "h", "d", "bw", "c"),
    [
        (AXIS_A, AXIS_B, AXIS_K, 0.1, 3, AXIS_B, AXIS_C),
        (AXIS_A, AXIS_B, AXIS_K, 0.25, 0, AXIS_B, AXIS_C),
        (RNG_A, RNG_B, RNG_K, 0.2, 2, RNG_BW, RNG_C),
    ],
    ids=["axis-d3", "axis-d0", "coupled-3-state"],
)
def test_sampled_hinf_bounds_and_matches_a_dense_sweep(a, b, k, h, d, bw, c) -> None:
    result = sampled_hinf_norm(a, b, k, h, delay_samples=d, B_w=bw, C=c)
    theta = np.linspace(0.0, math.pi, 200_001)
    s = _discrete_sweep(a, b, k, h, d, bw, c, theta)
    i = int(np.argmax(s))
    fine = np.linspace(theta[max(i - 1, 0)], theta[min(i + 1, len(theta) - 1)], 20_001)
    peak = max(float(s.max()), float(_discrete_sweep(a, b, k, h, d, bw, c, fine).max()))
    assert result.finite
    assert peak <= result.value * (1.0 + 1e-10)
    assert result.value == pytest.approx(peak, rel=1e-6)


def test_paper_axes_sampled_at_20_hz_against_a_dense_sweep() -> None:
    a, _, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    k = gain_matrix(paper.GAIN)
    result = sampled_hinf_norm(a, b, k, 0.05, delay_samples=10, C=c)
    theta = np.linspace(0.0, math.pi, 100_001)
    s = _discrete_sweep(a, b, k, 0.05, 10, b, c, theta)
    i = int(np.argmax(s))
    fine = np.linspace(theta[i - 1], theta[i + 1], 20_001)
    peak = max(float(s.max()), float(_discrete_sweep(a, b, k, 0.05, 10, b, c, fine).max()))
    assert peak <= result.value * (1.0 + 1e-10)
    assert result.value == pytest.approx(peak, rel=1e-6)
    assert result.frequency == pytest.approx(fine[np.argmax(_discrete_sweep(a, b, k, 0.05, 10, b, c, fine))] / 0.05)


def test_unstable_sampled_loop_is_infinite_not_a_number() -> None:
    # the paper axis with d h = 2 s, beyond its delay margin
    a, _, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    k = gain_matrix(paper.GAIN)
    h2 = sampled_h2_norm(a, b, k, 0.1, delay_samples=20, C=c)
    hinf = sampled_hinf_norm(a, b, k, 0.1, delay_samples=20, C=c)
    assert h2.value == math.inf and not h2.finite and "unstable" in str(h2)
    assert hinf.value == math.inf and math.isnan(hinf.frequency) and "infinite" in str(hinf)
    assert h2.spectral_radius > 1.0


def test_bad_input_is_refused_naming_the_parameter() -> None:
    with pytest.raises(SpecificationError, match="period"):
        sampled_h2_norm(AXIS_A, AXIS_B, AXIS_K, -0.1, C=AXIS_C)
    with pytest.raises(SpecificationError, match="delay_samples"):
        sampled_hinf_norm(AXIS_A, AXIS_B, AXIS_K, 0.1, delay_samples=-1, C=AXIS_C)
    with pytest.raises(DimensionError, match="C"):
        sampled_hinf_norm(AXIS_A, AXIS_B, AXIS_K, 0.1, C=[[1.0, 0.0, 0.0]])
    with pytest.raises(DimensionError, match="B_w"):
        sampled_h2_norm(AXIS_A, AXIS_B, AXIS_K, 0.1, B_w=[[1.0], [0.0], [0.0]], C=AXIS_C)
    with pytest.raises(SpecificationError, match="intensity"):
        sampled_h2_norm(AXIS_A, AXIS_B, AXIS_K, 0.1, C=AXIS_C, intensity=[[-1.0]])
    with pytest.raises(SpecificationError, match="A"):
        sampled_h2_norm([[np.nan, 1.0], [0.0, 0.0]], AXIS_B, AXIS_K, 0.1, C=AXIS_C)
    with pytest.raises(SpecificationError, match="B_w and C"):
        sampled_hinf_norm(AXIS_A, AXIS_B, AXIS_K, 0.1, C=[[0.0, 0.0]])


# ------------------------------------------------------------------------------ the intersample L2 gain
def _held_input_gain(a, b, k, h, d, bw, c, pieces: int) -> float:
    """The L2 gain over w constant on ``pieces`` sub-intervals of each period, output energy integrated exactly.

    Written on the history state (x_k, x_{k−1}, …, x_{k−d}) with u_k = K x_{k−d} (nothing shared with the module):
    per substep the state and the output energy ∫|C x|² of (x, u, w) held, by Van Loan's exponential; the lifted
    system (one period, ``pieces`` inputs and outputs) is swept densely on the unit circle and refined at the peak.
    """
    n, m, q = a.shape[0], b.shape[1], bw.shape[1]
    hs = h / pieces
    g = np.zeros((n + m + q, n + m + q))
    g[:n, :n], g[:n, n : n + m], g[:n, n + m :] = a, b, bw
    step = scipy.linalg.expm(g * hs)[:n]
    weight = np.zeros_like(g)
    weight[:n, :n] = c.T @ c
    big = np.block([[-g.T, weight], [np.zeros_like(g), g]])
    e = scipy.linalg.expm(big * hs)
    energy = e[len(g) :, len(g) :].T @ e[: len(g), len(g) :]
    val, vec = np.linalg.eigh(0.5 * (energy + energy.T))
    root = (vec * np.sqrt(np.maximum(val, 0.0))).T
    size = n * (d + 1)
    cols = size + pieces * q
    # x(t_k) = history[0:n]; u_k = K · history[d n:(d+1) n]
    x = np.zeros((n, cols))
    x[:, :n] = np.eye(n)
    u = np.zeros((m, cols))
    u[:, d * n : (d + 1) * n] = k
    outputs = []
    for j in range(pieces):
        w = np.zeros((q, cols))
        w[:, size + j * q : size + (j + 1) * q] = np.eye(q)
        outputs.append(root @ np.vstack((x, u, w)))
        x = step @ np.vstack((x, u, w))
    nxt = np.zeros((size, cols))
    nxt[:n] = x
    nxt[n:, : d * n] = np.eye(d * n)
    cz = np.vstack([o[:, :size] for o in outputs])
    dz = np.vstack([o[:, size:] for o in outputs])
    f, gin = nxt[:, :size], nxt[:, size:]

    def sigma(theta: float) -> float:
        tf = cz @ np.linalg.solve(np.exp(1j * theta) * np.eye(size) - f, gin) + dz
        return float(np.linalg.svd(tf, compute_uv=False)[0]) / math.sqrt(hs)

    grid = np.linspace(0.0, math.pi, 4001)
    values = [sigma(t) for t in grid]
    i = int(np.argmax(values))
    fine = np.linspace(grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)], 2001)
    return max(max(values), max(sigma(t) for t in fine))


@pytest.mark.parametrize(
    ("a", "b", "k", "h", "d", "bw", "c"),
    [
        (AXIS_A, AXIS_B, AXIS_K, 0.25, 2, AXIS_B, AXIS_C),
        (RNG_A, RNG_B, RNG_K, 0.2, 1, RNG_BW, RNG_C),
    ],
    ids=["axis-d2", "coupled-3-state"],
)
def test_l2_gain_is_the_limit_of_the_held_input_gains(a, b, k, h, d, bw, c) -> None:
    exact = sampled_l2_gain(a, b, k, h, delay_samples=d, B_w=bw, C=c)
    assert exact.finite and exact.bracket_certified
    lower = [_held_input_gain(a, b, k, h, d, bw, c, pieces) for pieces in (8, 16, 32)]
    # a subset of the inputs: each is below the gain, and they rise to it at second order in the substep
    assert all(v <= exact.value * (1.0 + 1e-9) for v in lower)
    assert lower[0] < lower[1] < lower[2]
    gaps = [exact.value - v for v in lower]
    assert 3.5 <= gaps[0] / gaps[1] <= 4.5 and 3.5 <= gaps[1] / gaps[2] <= 4.5
    richardson = lower[2] + (lower[2] - lower[1]) / 3.0
    assert richardson == pytest.approx(exact.value, rel=2e-7)


def test_l2_gain_of_the_paper_loop_tends_to_the_continuous_norm() -> None:
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    k = gain_matrix(paper.GAIN)
    hinf = hinf_norm(a, [a_d], [0.5], b, c).value
    gaps = []
    for d in (5, 10, 20):
        result = sampled_l2_gain(a, b, k, 0.5 / d, delay_samples=d, C=c)
        assert result.bracket_certified
        gaps.append(result.value - hinf)
    assert all(g > 0.0 for g in gaps)
    for coarse, fine in itertools.pairwise(gaps):
        assert 0.425 <= fine / coarse <= 0.575
    unstable = sampled_l2_gain(a, b, k, 0.1, delay_samples=20, C=c)
    assert unstable.value == math.inf and "infinite" in str(unstable)
