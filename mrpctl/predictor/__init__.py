"""Delay compensation by prediction: the linearised predictor loop, its exact stability and its inertia margin.

The controller sees y(t) = x(t − τ) and applies u = K x̂ with the prediction (finite spectrum
assignment, Manitius-Olbrot / Artstein) made with its own model inertia J_m (B_m = [0; ¼ J_m⁻¹])::

    x̂(t) = e^{Aτ} y(t) + ∫_{t−τ}^{t} e^{A(t−s)} B_m u(s) ds                    (continuous)
    x̂_k = Φ^d y_k + Σ_{j=0}^{d−1} Φ^{d−1−j} Γ_m u_{k−d+j},  y_k = x_{k−d}       (sampled, τ = d h)

while the plant ẋ = A x + B u has B = [0; ¼ J⁻¹], J ≠ J_m. Differentiating the prediction and using
the plant equation eliminates x: the prediction itself obeys a delay equation,

    dx̂/dt = (A + B_m K) x̂(t) + e^{Aτ} (B − B_m) K x̂(t − τ)                    (continuous)
    x̂_{k+1} = (Φ + Γ_m K) x̂_k + Φ^d (Γ − Γ_m) K x̂_{k−d}                         (sampled)

and x → 0 exactly when x̂ → 0 (Φ^d is invertible). With J = J_m the delayed term vanishes and the
loop is the undelayed one (the finite spectrum of A + B K); the inertia error alone limits the gains.
Exact tests: the continuous equation by the crossing method of
[`mrpctl.design.delay_margin`][mrpctl.design.delay_margin]
(at the given τ, with the delayed matrix that itself depends on τ); the sampled one by the spectral
radius of the lifted (block companion) matrix of size n (d + 1), reduced per axis to the roots of a
scalar polynomial of degree d + 2 when the loop splits into three axes. See ``design/predictor.md``.
"""

from __future__ import annotations

from mrpctl.predictor.analysis import (
    MarginInterval,
    MismatchMargin,
    PredictorDesign,
    PredictorStability,
    StabilityMethod,
    StabilityStatus,
    inertia_mismatch_margin,
    lifted_spectral_radius,
    margin_side,
    margin_side_bracket,
    perturbed_spacecraft,
    predictor_loop_matrices,
    predictor_stability,
    sampled_predictor_matrices,
    synthesize_predictor_pd,
)
from mrpctl.predictor.controller import OnPredicted, Predictor, PredictorForm

__all__ = [
    "MarginInterval",
    "MismatchMargin",
    "OnPredicted",
    "Predictor",
    "PredictorDesign",
    "PredictorForm",
    "PredictorStability",
    "StabilityMethod",
    "StabilityStatus",
    "inertia_mismatch_margin",
    "lifted_spectral_radius",
    "margin_side",
    "margin_side_bracket",
    "perturbed_spacecraft",
    "predictor_loop_matrices",
    "predictor_stability",
    "sampled_predictor_matrices",
    "synthesize_predictor_pd",
]
