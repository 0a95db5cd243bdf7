"""Margins of the sampled loop against python-control's `stability_margins` on the discrete loop transfer
function, against the lifted closed loop's spectral radius on either side of each margin, and against the
continuous delayed loop as h -> 0."""

from __future__ import annotations

import math
import warnings

import control as ct
import numpy as np
import pytest

from mrpctl import paper
from mrpctl.conventions import pd_from_gain
from mrpctl.design.performance import loop_margins_delayed, spacecraft_margins
from mrpctl.design.sampled import lifted_matrices, sampled_stability
from mrpctl.design.sampled_margins import loop_margins_sampled
from mrpctl.errors import SpecificationError
from mrpctl.model import gain_matrix, plant_model

A_AXIS = np.array([[0.0, 1.0], [0.0, 0.0]])
B_AXIS = np.array([[0.0], [1.0]])


def _axis_gain(axis: int) -> np.ndarray:
    k1, k2 = pd_from_gain(paper.SPACECRAFT, paper.GAIN)
    return np.array([[float(np.diag(k1)[axis]), float(np.diag(k2)[axis])]])


def _python_control(k: np.ndarray, h: float, d: int) -> tuple[float, float, float, float]:
    """(gm, pm in deg, ω_pc, ω_gc) of L(z) = −K (zI − Φ)⁻¹ Γ z^{−d} by python-control."""
    phi, gamma = lifted_matrices(A_AXIS, B_AXIS, h)
    loop = ct.tf(ct.ss(phi, gamma, -k, 0, dt=h))
    if d:
        loop = loop * ct.tf([1.0], [1.0] + [0.0] * d, dt=h)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its fallback to the frequency-response method
        gm, pm, _, wpc, wgc, _ = ct.stability_margins(loop)
    return float(gm), float(pm), float(wpc), float(wgc)


@pytest.mark.parametrize(("axis", "h", "d"), [(0, 0.05, 10), (1, 0.1, 5), (2, 0.025, 20), (0, 0.5, 1)])
def test_one_axis_matches_python_control(axis: int, h: float, d: int) -> None:
    k = _axis_gain(axis)
    ours = loop_margins_sampled(A_AXIS, B_AXIS, k, h, delay_samples=d)
    gm, pm, wpc, wgc = _python_control(k, h, d)
    assert ours.stable
    assert ours.gain_margin == pytest.approx(gm, rel=1e-6)
    assert math.degrees(ours.phase_margin) == pytest.approx(pm, rel=1e-6)
    assert ours.phase_crossover == pytest.approx(wpc, rel=1e-6)
    assert ours.gain_crossover == pytest.approx(wgc, rel=1e-6)


@pytest.mark.parametrize(("h", "d"), [(0.05, 10), (0.02, 0), (0.1, 5)])
def test_each_margin_is_where_the_lifted_loop_loses_stability(h: float, d: int) -> None:
    """Just inside a margin the lifted loop is stable, just outside it is not (its exact spectral radius); at d = 0
    the gain margin sits at the Nyquist frequency (z = −1), which python-control's fallback misses (it reports
    an infinite gain margin there)."""
    k = _axis_gain(0)
    ours = loop_margins_sampled(A_AXIS, B_AXIS, k, h, delay_samples=d)
    assert math.isfinite(ours.gain_margin)
    for factor, stable in ((1.0 - 1e-6, True), (1.0 + 1e-6, False)):
        radius = sampled_stability(A_AXIS, B_AXIS, k * ours.gain_margin * factor, h, delay_samples=d).spectral_radius
        assert (radius < 1.0) is stable
    extra = ours.delay_margin_samples
    assert extra is not None and extra >= 0
    assert sampled_stability(A_AXIS, B_AXIS, k, h, delay_samples=d + extra).stable
    assert not sampled_stability(A_AXIS, B_AXIS, k, h, delay_samples=d + extra + 1).stable
    assert ours.delay_margin == pytest.approx(extra * h)
    # the phase margin: a phase lag φ on the loop puts an eigenvalue of L on −1 at the gain crossover
    phi, gamma = lifted_matrices(A_AXIS, B_AXIS, h)
    z = np.exp(1j * ours.gain_crossover * h)
    value = complex((-k @ np.linalg.solve(z * np.eye(2) - phi, gamma))[0, 0] * z ** (-d))
    assert abs(value) == pytest.approx(1.0, abs=1e-9)
    assert math.pi - abs(np.angle(value)) == pytest.approx(ours.phase_margin, abs=1e-9)
    if d == 0:
        assert ours.phase_crossover == pytest.approx(math.pi / h)
        assert math.isinf(_python_control(k, h, d)[0])


def test_the_coupled_loop_is_its_weakest_axis_and_tends_to_the_continuous_loop() -> None:
    plant = plant_model(paper.SPACECRAFT)
    k = gain_matrix(paper.GAIN)
    axes = [loop_margins_sampled(A_AXIS, B_AXIS, _axis_gain(i), 0.05, delay_samples=10) for i in range(3)]
    coupled = loop_margins_sampled(plant.A, plant.B, k, 0.05, delay_samples=10)
    assert coupled.gain_margin == pytest.approx(min(m.gain_margin for m in axes), rel=1e-9)
    assert coupled.phase_margin == pytest.approx(min(m.phase_margin for m in axes), rel=1e-9)
    assert coupled.delay_margin_samples == min(m.delay_margin_samples or 0 for m in axes)
    # h -> 0 on the weakest axis (the coupled loop's margins are its): towards the continuous delayed loop
    continuous = spacecraft_margins(paper.SPACECRAFT, paper.GAIN, 0.5).axes[2]
    assert continuous.gain_margin == pytest.approx(loop_margins_delayed(plant.A, plant.B, k, 0.5).gain_margin, rel=1e-9)
    errors = []
    for h in (0.05, 0.01, 0.002):
        sampled = loop_margins_sampled(A_AXIS, B_AXIS, _axis_gain(2), h, delay_samples=round(0.5 / h))
        errors.append(abs(sampled.gain_margin - continuous.gain_margin))
        # the hold adds about h/2 of lag: the sampled delay margin lies below the continuous one, within a sample
        assert sampled.delay_margin <= continuous.delay_margin
        assert sampled.delay_margin >= continuous.delay_margin - h / 2 - h
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-2 * continuous.gain_margin


def test_an_unstable_loop_says_so() -> None:
    ours = loop_margins_sampled(A_AXIS, B_AXIS, _axis_gain(0), 0.05, delay_samples=40)
    assert not ours.stable and ours.spectral_radius > 1.0 and ours.delay_margin_samples == -1
    assert math.isnan(ours.delay_margin) and "UNSTABLE" in str(ours)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"period": 0.0}, "period"),
        ({"period": -0.1}, "period"),
        ({"period": math.nan}, "period"),
        ({"delay_samples": -1}, "delay_samples"),
        ({"delay_samples": 1.5}, "delay_samples"),
        ({"K": np.zeros((1, 2))}, "K is zero"),
        ({"K": np.zeros((1, 3))}, "K"),
    ],
)
def test_bad_input_names_the_parameter(kwargs: dict[str, object], words: str) -> None:
    args = {"A": A_AXIS, "B": B_AXIS, "K": _axis_gain(0), "period": 0.05, **kwargs}
    with pytest.raises((SpecificationError, ValueError)) as info:
        loop_margins_sampled(args.pop("A"), args.pop("B"), args.pop("K"), args.pop("period"), **args)
    assert words in str(info.value)
