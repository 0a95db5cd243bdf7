"""Robust PD synthesis over the inertia polytope and the sampled delay, checked by the exact references."""

from __future__ import annotations

import numpy as np
import pytest

from mrpctl import paper
from mrpctl.design.polytope import exact_polytope_margin, inertia_polytope
from mrpctl.design.robust import DelayModel, RobustStatus, synthesize_robust_pd
from mrpctl.design.sampled import sampled_stability, spacecraft_axes
from mrpctl.errors import SpecificationError


def test_robust_constant_delay_over_20_percent_box() -> None:
    res = synthesize_robust_pd(paper.SPACECRAFT, 0.5, tolerance=0.2, order=1, rtol=0.02)
    assert res.status is RobustStatus.SYNTHESIZED and res.model is DelayModel.CONSTANT
    assert res.gains is not None and res.certificate is not None and res.certificate.certified
    poly = inertia_polytope(paper.SPACECRAFT, 0.2)
    assert exact_polytope_margin(poly, res.gains.K, points=21) > 0.5
    # Never above the nominal exact bound: margin of the unit-frequency loop / tau.
    from mrpctl.design import delay_margin

    unit = delay_margin([[0.0, 1.0], [0.0, 0.0]], [[0.0, 0.0], [-1.0, -2.0]]).margin
    assert 0.0 < res.omega_n < unit / 0.5


def test_robust_sampled_loop_is_stable_when_lifted() -> None:
    res = synthesize_robust_pd(paper.SPACECRAFT, 0.05, period=0.01, order=0, rtol=0.1)
    assert res.status is RobustStatus.SYNTHESIZED and res.model is DelayModel.SAMPLED
    assert res.gains is not None
    for a, b, k in spacecraft_axes(paper.SPACECRAFT, res.gains.K):
        assert sampled_stability(a, b, k, 0.01, delay_samples=5).stable


def test_refusals() -> None:
    with pytest.raises(SpecificationError, match="integer number of samples"):
        synthesize_robust_pd(paper.SPACECRAFT, 0.0105, period=0.01)
    with pytest.raises(SpecificationError, match="either period"):
        synthesize_robust_pd(paper.SPACECRAFT, 0.5, period=0.01, tau_min=0.1)
    assert np.isfinite(paper.TAU)


def test_solver_failure_during_the_search_is_counted_not_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    import mrpctl.design.robust as robust
    from mrpctl.design.lmi import CertificateStatus
    from mrpctl.design.polytope import PolytopeCertificate

    real = robust.certify_polytope
    calls: list[int] = []

    def flaky(*args: object, **kwargs: object) -> PolytopeCertificate:
        calls.append(1)
        if len(calls) == 2:  # the first doubling step
            return PolytopeCertificate(CertificateStatus.SOLVER_FAILED, 1, 0.5, 0, (), 0.0, "simulated failure")
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(robust, "certify_polytope", flaky)
    res = synthesize_robust_pd(paper.SPACECRAFT, 0.5, tolerance=0.2, order=1, rtol=0.1)
    assert res.status is RobustStatus.SYNTHESIZED and res.certificate is not None and res.certificate.certified
    assert "1 certificate test(s) SOLVER_FAILED" in res.reason
    assert exact_polytope_margin(inertia_polytope(paper.SPACECRAFT, 0.2), res.gains.K, points=11) > 0.5  # type: ignore[union-attr]
