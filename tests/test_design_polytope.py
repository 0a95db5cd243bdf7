"""Inertia polytope: containment of J^-1, the paper's K over +/-20 %, soundness against the exact grid."""

from __future__ import annotations

import numpy as np
import pytest

from mrpctl import Spacecraft, paper
from mrpctl.design.polytope import (
    Functional,
    certify_polytope,
    exact_polytope_margin,
    inertia_polytope,
    max_stable_tolerance,
)
from mrpctl.errors import SpecificationError


def test_inverse_box_contains_every_sampled_inertia(rng: np.random.Generator) -> None:
    poly = inertia_polytope(paper.SPACECRAFT, 0.1, product_bound=5.0)
    j0 = np.diag(paper.INERTIA)
    for _ in range(500):
        j = j0 * (1 + rng.uniform(-0.1, 0.1, size=3)) * np.eye(3)
        off = rng.uniform(-5.0, 5.0, size=3)
        j[0, 1] = j[1, 0] = off[0]
        j[0, 2] = j[2, 0] = off[1]
        j[1, 2] = j[2, 1] = off[2]
        assert poly.contains_inverse(j)
    assert len(poly.vertices) == 64


def test_diagonal_box_is_exact_and_flags_the_nonphysical_vertex() -> None:
    poly = inertia_polytope(paper.SPACECRAFT, 0.2)
    # (168, 80, 64) breaks the triangle inequality (168 > 144): kept (a superset is sound), and counted.
    assert len(poly.vertices) == 8 and poly.nonphysical == 1
    corners = {tuple(np.round(1.0 / np.diag(v), 9)) for v in poly.vertices}
    expected = {
        tuple(np.round([f0 * 140, f1 * 100, f2 * 80], 9)) for f0 in (0.8, 1.2) for f1 in (0.8, 1.2) for f2 in (0.8, 1.2)
    }
    assert corners == expected


def test_paper_gain_over_20_percent_box_against_the_exact_worst_margin() -> None:
    poly = inertia_polytope(paper.SPACECRAFT, 0.2)
    exact = exact_polytope_margin(poly, paper.GAIN, points=21)
    # The worst grid point is the smallest inertia of the smallest axis: 0.8 * 80 kg m^2.
    a_d = [[0.0, 0.0], [paper.GAIN_SIGMA / (4 * 64.0), paper.GAIN_OMEGA / (4 * 64.0)]]
    from mrpctl.design import delay_margin

    assert exact == pytest.approx(delay_margin([[0.0, 1.0], [0.0, 0.0]], a_d).margin, rel=1e-9)
    # One functional common to both ends of each axis: certified at 0.85x (measured 0.856x, design/lmi.md section 7),
    # never above the exact worst margin. The 0.99x needs the vertex-dependent functional (the default;
    # tests/test_design_polytope_vertex.py).
    assert certify_polytope(poly, paper.GAIN, 0.85 * exact, order=2, functional=Functional.COMMON).certified
    assert not certify_polytope(poly, paper.GAIN, 1.01 * exact, order=2, functional=Functional.COMMON).certified


def test_tolerance_beyond_exact_limit_is_never_certified_and_certified_is_stable() -> None:
    tol_exact = max_stable_tolerance(paper.SPACECRAFT, paper.GAIN, 0.5, points=11, rtol=1e-3)
    assert 0.0 < tol_exact < 1.0
    assert not certify_polytope(
        inertia_polytope(paper.SPACECRAFT, min(0.999, 1.01 * tol_exact)), paper.GAIN, 0.5
    ).certified
    poly = inertia_polytope(paper.SPACECRAFT, 0.9 * tol_exact)
    if certify_polytope(poly, paper.GAIN, 0.5).certified:
        assert exact_polytope_margin(poly, paper.GAIN, points=41) > 0.5


@pytest.mark.slow
def test_products_of_inertia_certificate_is_stable_on_the_grid() -> None:
    k = paper.GAIN
    poly = inertia_polytope(paper.SPACECRAFT, 0.05, product_bound=3.0)
    cert = certify_polytope(poly, k, 0.5, order=0)
    if cert.certified:
        assert exact_polytope_margin(poly, k, points=2) > 0.5
    assert cert.vertices == 64


def test_refusals() -> None:
    with pytest.raises(SpecificationError, match="tolerance"):
        inertia_polytope(paper.SPACECRAFT, 1.0)
    with pytest.raises(SpecificationError, match="diagonal"):
        inertia_polytope(Spacecraft([[140, 1, 0], [1, 100, 0], [0, 0, 80]]), 0.1)
