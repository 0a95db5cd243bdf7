"""Design: PD gains, delay-dependent LMI certificates, the exact delay margin and gain synthesis.

cvxpy and Clarabel are used only inside this package, and imported lazily (on the first solve),
so ``import mrpctl.design`` is cheap.
"""

from __future__ import annotations

from mrpctl.design.gains import AxisDamping, GainAnalysis, PDGains, analyze_gains, pd_gains
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
from mrpctl.design.margin import Crossing, DelayMargin, delay_margin
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
    "GainAnalysis",
    "LMISynthesis",
    "LinearizedLoop",
    "PDGains",
    "PDSynthesis",
    "Positivity",
    "SearchStatus",
    "SynthesisStatus",
    "analyze_gains",
    "certify",
    "criterion_name",
    "delay_margin",
    "linearized_loop",
    "lmi_blocks",
    "max_certified_delay",
    "pd_gains",
    "synthesize_lmi",
    "synthesize_pd",
]
