"""PD gains and damping analysis, checked against the plant's own closed-loop eigenvalues."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrpctl import Spacecraft, paper, plant_model
from mrpctl.design import analyze_gains, pd_gains
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import pd_from_gain


@pytest.fixture
def spacecraft() -> Spacecraft:
    return paper.SPACECRAFT


@pytest.mark.parametrize(("zeta", "omega_n"), [(1.0, 0.5), (1.5, [0.2, 0.4, 0.8]), ([1.0, 2.0, 3.0], 1.0)])
def test_pd_gains_place_the_plant_poles(spacecraft: Spacecraft, zeta: object, omega_n: object) -> None:
    gains = pd_gains(spacecraft, zeta=zeta, omega_n=omega_n)
    z = np.broadcast_to(zeta, 3)
    w = np.broadcast_to(omega_n, 3)
    # Independent: eigenvalues of A + B K from the CasADi plant's matrices.
    a, a_d = plant_model(spacecraft).closed_loop_matrices(gains.K)
    plant_poles = np.sort_complex(np.linalg.eigvals(a + a_d))
    expected = np.sort_complex(
        np.concatenate([np.roots([1.0, 2 * zi * wi, wi * wi]) for zi, wi in zip(z, w, strict=True)])
    )
    np.testing.assert_allclose(plant_poles, expected, atol=1e-6)
    np.testing.assert_allclose(np.sort_complex(gains.poles.ravel()), expected, atol=1e-12)
    k1, k2 = pd_from_gain(spacecraft, gains.K)
    np.testing.assert_allclose(k1, gains.K1, atol=1e-15)
    np.testing.assert_allclose(k2, gains.K2, atol=1e-15)
    np.testing.assert_allclose(gains.K[:, :3], 4 * spacecraft.inertia @ gains.K1)
    assert gains.overdamped
    assert "omega_n" in str(gains)


def test_underdamped_needs_explicit_request(spacecraft: Spacecraft) -> None:
    with pytest.raises(SpecificationError, match="allow_underdamped"):
        pd_gains(spacecraft, zeta=0.7, omega_n=1.0)
    gains = pd_gains(spacecraft, zeta=0.7, omega_n=1.0, allow_underdamped=True)
    assert not gains.overdamped
    assert np.all(np.abs(gains.poles.imag) > 0)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"zeta": -1.0, "omega_n": 1.0}, SpecificationError, "zeta must be > 0"),
        ({"zeta": -1.0, "omega_n": 1.0, "allow_underdamped": True}, SpecificationError, "zeta must be > 0"),
        ({"zeta": 1.0, "omega_n": 0.0}, SpecificationError, "omega_n must be > 0"),
        ({"zeta": 1.0, "omega_n": -2.0}, SpecificationError, "omega_n must be > 0"),
        ({"zeta": 1.0, "omega_n": math.nan}, SpecificationError, "omega_n must be finite"),
        ({"zeta": [1.0, 1.0], "omega_n": 1.0}, DimensionError, "zeta: expected"),
    ],
)
def test_pd_gains_bad_input(spacecraft: Spacecraft, kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        pd_gains(spacecraft, **kwargs)


def test_omega_n_is_required(spacecraft: Spacecraft) -> None:
    with pytest.raises(TypeError):
        pd_gains(spacecraft, zeta=1.0)  # type: ignore[call-arg]


def test_paper_gain_is_underdamped_in_our_convention(spacecraft: Spacecraft) -> None:
    analysis = analyze_gains(spacecraft, paper.GAIN)
    assert analysis.decoupled and analysis.stable
    assert not analysis.overdamped
    for axis, inertia in zip(analysis.axes, paper.INERTIA, strict=True):
        k1 = paper.GAIN_SIGMA / (4 * inertia)
        k2 = paper.GAIN_OMEGA / (4 * inertia)
        omega_n = math.sqrt(-k1)
        assert axis.omega_n == pytest.approx(omega_n, rel=1e-12)
        assert axis.zeta == pytest.approx(-k2 / (2 * omega_n), rel=1e-12)
        assert not axis.overdamped
    assert [round(a.zeta, 2) for a in analysis.axes] == [0.41, 0.49, 0.54]
    # Cross-check with the plant: complex poles of A + B K.
    a, a_d = plant_model(spacecraft).closed_loop_matrices(paper.GAIN)
    assert np.all(np.abs(np.linalg.eigvals(a + a_d).imag) > 0.3)
    assert "underdamped" in str(analysis)


def test_paper_gain_read_with_the_printed_convention_is_overdamped(spacecraft: Spacecraft) -> None:
    # The paper prints K = [4 J K1, J K2]: its K2 = -163.08 / J. In our convention that loop needs
    # the rate block 4 J K2 = 4 x (-163.08).
    printed = np.hstack((paper.GAIN_SIGMA * np.eye(3), 4 * paper.GAIN_OMEGA * np.eye(3)))
    analysis = analyze_gains(spacecraft, printed)
    assert analysis.overdamped
    for axis, inertia in zip(analysis.axes, paper.INERTIA, strict=True):
        expected = (-paper.GAIN_OMEGA / inertia) / (2 * math.sqrt(-paper.GAIN_SIGMA / (4 * inertia)))
        assert axis.zeta == pytest.approx(expected, rel=1e-12)
        assert axis.zeta > 1.0


def test_coupled_gain_reports_poles_only(rng: np.random.Generator) -> None:
    spacecraft = Spacecraft([[10.0, 1.0, 0.0], [1.0, 12.0, 0.5], [0.0, 0.5, 9.0]])
    gains = pd_gains(spacecraft, zeta=2.0, omega_n=1.0)
    analysis = analyze_gains(spacecraft, gains.K)
    # K1 = -I and K2 = -4I are diagonal even though J is not: still decoupled and overdamped.
    assert analysis.decoupled and analysis.overdamped
    k = gains.K + 0.5 * rng.normal(size=(3, 6))
    coupled = analyze_gains(spacecraft, k)
    assert not coupled.decoupled
    a, a_d = plant_model(spacecraft).closed_loop_matrices(k)
    np.testing.assert_allclose(np.sort_complex(coupled.poles), np.sort_complex(np.linalg.eigvals(a + a_d)))
    assert coupled.overdamped == bool(np.all(np.abs(coupled.poles.imag) < 1e-9) and np.all(coupled.poles.real < 0))
    assert "coupled" in str(coupled)


def test_analyze_gains_bad_shape(spacecraft: Spacecraft) -> None:
    with pytest.raises(DimensionError, match="K: expected shape"):
        analyze_gains(spacecraft, np.zeros((3, 3)))


def test_critically_damped_design_stays_overdamped_after_round_trip() -> None:
    """ζ = 1 gains must not read as underdamped because of rounding in K -> (K1, K2)."""

    for omega_n in (0.1, 1.29477, 3.7):
        gains = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=omega_n)
        analysis = analyze_gains(paper.SPACECRAFT, gains.K)
        assert analysis.overdamped
        for axis in analysis.axes:
            assert np.all(axis.poles.imag == 0.0)
            assert np.allclose(axis.poles.real, -omega_n, rtol=1e-9)
