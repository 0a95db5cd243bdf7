"""Design: PD gains, delay-dependent LMI certificates, the exact delay margin and gain synthesis.

cvxpy and Clarabel are used only inside this package, and imported lazily (on the first solve),
so ``import mrpctl.design`` is cheap.
"""

from __future__ import annotations

from mrpctl.design.gains import AxisDamping, GainAnalysis, PDGains, analyze_gains, pd_gains
from mrpctl.design.interval import (
    DelayRate,
    IntervalCertificate,
    IntervalDelayCertification,
    RateKind,
    certify_interval,
    max_certified_interval_delay,
)
from mrpctl.design.lmi import (
    JENSEN,
    WIRTINGER,
    BlockMargin,
    Certificate,
    CertificateStatus,
    DelayCertification,
    Positivity,
    SearchStatus,
    certify,
    criterion_name,
    lmi_blocks,
    max_certified_delay,
)
from mrpctl.design.loop import LinearizedLoop, linearized_loop
from mrpctl.design.looped import LoopedCertificate, certify_looped, max_looped_period
from mrpctl.design.margin import Crossing, DelayMargin, delay_margin
from mrpctl.design.polytope import (
    Functional,
    InertiaPolytope,
    PolytopeCertificate,
    certify_polytope,
    certify_vertices,
    exact_polytope_margin,
    inertia_polytope,
    max_certified_tolerance,
    max_stable_tolerance,
)
from mrpctl.design.robust import DelayModel, RobustPDSynthesis, RobustStatus, synthesize_robust_pd
from mrpctl.design.sampled import (
    SampledCertification,
    SampledCriterion,
    SampledStability,
    certify_sampled,
    lifted_matrices,
    max_certified_delay_samples,
    max_certified_period,
    max_stable_delay_samples,
    max_stable_period,
    sampled_stability,
    spacecraft_axes,
)
from mrpctl.design.synthesis import LMISynthesis, PDSynthesis, SynthesisStatus, synthesize_lmi, synthesize_pd

__all__ = [
    "JENSEN",
    "WIRTINGER",
    "AxisDamping",
    "BlockMargin",
    "Certificate",
    "CertificateStatus",
    "Crossing",
    "DelayCertification",
    "DelayMargin",
    "DelayModel",
    "DelayRate",
    "Functional",
    "GainAnalysis",
    "InertiaPolytope",
    "IntervalCertificate",
    "IntervalDelayCertification",
    "LMISynthesis",
    "LinearizedLoop",
    "LoopedCertificate",
    "PDGains",
    "PDSynthesis",
    "PolytopeCertificate",
    "Positivity",
    "RateKind",
    "RobustPDSynthesis",
    "RobustStatus",
    "SampledCertification",
    "SampledCriterion",
    "SampledStability",
    "SearchStatus",
    "SynthesisStatus",
    "analyze_gains",
    "certify",
    "certify_interval",
    "certify_looped",
    "certify_polytope",
    "certify_sampled",
    "certify_vertices",
    "criterion_name",
    "delay_margin",
    "exact_polytope_margin",
    "inertia_polytope",
    "lifted_matrices",
    "linearized_loop",
    "lmi_blocks",
    "max_certified_delay",
    "max_certified_delay_samples",
    "max_certified_interval_delay",
    "max_certified_period",
    "max_certified_tolerance",
    "max_looped_period",
    "max_stable_delay_samples",
    "max_stable_period",
    "max_stable_tolerance",
    "pd_gains",
    "sampled_stability",
    "spacecraft_axes",
    "synthesize_lmi",
    "synthesize_pd",
    "synthesize_robust_pd",
]
