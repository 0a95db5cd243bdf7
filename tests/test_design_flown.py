"""Joint verdicts on the loop as flown (mrpctl.design.flown) against independent exact references.

Every combination of the flown options (sample rate on/off x jitter on/off x inertia box on/off) is
run at a gain whose exact answer is stable and at one where it is unstable. The references are
written here, not taken from the library: the per-axis lifted loop of the double integrator in
closed form (Phi = [[1, h], [0, 1]], Gamma = b [h^2/2; h]) with its own companion matrix, and the
closed-form delay margin of sigma'' = b (k1 sigma + k2 sigma')(t - tau). No combination may report
VERIFIED for a loop the reference finds unstable.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrpctl import paper
from mrpctl.design import FlownStatus, pd_gains, verify_flown
from mrpctl.design.flown import CheckKind, CheckOutcome
from mrpctl.errors import SpecificationError
from mrpctl.spacecraft import Spacecraft

J0 = np.array(paper.INERTIA, dtype=float)
SC = Spacecraft(np.diag(J0))
TAU = 0.5
STABLE_K = np.asarray(paper.GAIN, dtype=float)  # stable at 20 Hz and continuous over +/-20 %
DESIGN_K = np.asarray(pd_gains(SC, zeta=1.0, omega_n=0.889707).K)  # `design --tau 0.5`: unstable at 2 Hz
FAST_K = np.asarray(pd_gains(SC, zeta=1.0, omega_n=1.06).K)  # 20 Hz nominal and continuous box stable, jointly not
EDGE_K = np.asarray(pd_gains(SC, zeta=1.0, omega_n=1.02).K)  # 20 Hz x +/-20 % stable (0.99933), not certified jointly
HOT_K = np.asarray(pd_gains(SC, zeta=1.0, omega_n=1.4).K)  # continuous margin 0.46 s < 0.5 s


def _lifted_radius(b: float, k1: float, k2: float, h: float, d: int) -> float:
    phi = np.array([[1.0, h], [0.0, 1.0]])
    gam = b * np.array([[h * h / 2.0], [h]])
    gk = gam @ np.array([[k1, k2]])
    n = 2 * (d + 1)
    m = np.zeros((n, n))
    m[:2, :2] = phi
    m[:2, 2 * d :] += gk
    if d:
        m[2:, :-2] = np.eye(2 * d)
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def _margin(b: float, k1: float, k2: float) -> float:
    # -w^2 = b (k1 + i w k2) e^{-i w tau}, k1, k2 < 0: one crossing, stable below it.
    a1, a2 = abs(b * k1), abs(b * k2)
    w = math.sqrt((a2 * a2 + math.sqrt(a2**4 + 4.0 * a1 * a1)) / 2.0)
    return math.atan(w * a2 / a1) / w


def _axes(K: np.ndarray, scale: float) -> list[tuple[float, float, float]]:
    return [(0.25 / (scale * J0[i]), K[i, i], K[i, 3 + i]) for i in range(3)]


def reference(K: np.ndarray, *, rate: float | None, tau_min: float | None, tol: float) -> tuple[bool, float]:
    """(exactly stable at 9 inertias per axis and every flown constant delay, largest lifted radius or nan)."""
    scales = np.linspace(1.0 - tol, 1.0 + tol, 9) if tol else np.array([1.0])
    if rate is None:
        lo = TAU if tau_min is None else tau_min
        del lo  # the margin is an interval from 0: the largest delay binds
        return all(_margin(b, k1, k2) > TAU for s in scales for b, k1, k2 in _axes(K, s)), math.nan
    h = 1.0 / rate
    d = round(TAU * rate)
    delays = [d] if tau_min is None else range(math.ceil(tau_min * rate - 1e-9), d + 1)
    rho = max(_lifted_radius(b, k1, k2, h, dd) for s in scales for b, k1, k2 in _axes(K, s) for dd in delays)
    return rho < 1.0, rho


COMBOS = [(rate, jitter, box) for rate in (None, 20.0) for jitter in (False, True) for box in (False, True)]


def _options(rate: float | None, jitter: bool, box: bool) -> dict[str, float]:
    out: dict[str, float] = {}
    if rate is not None:
        out["rate"] = rate
    if jitter:
        out["tau_min"] = 0.3
    if box:
        out["tolerance"] = 0.2
    return out


def _check_against_reference(K: np.ndarray, **options: float) -> tuple[FlownStatus, bool, float]:
    verdict = verify_flown(SC, K, TAU, grid=3, **options)
    stable, rho = reference(
        K, rate=options.get("rate"), tau_min=options.get("tau_min"), tol=options.get("tolerance", 0.0)
    )
    if not stable:
        assert verdict.status is not FlownStatus.VERIFIED, verdict
    if verdict.status is FlownStatus.UNSTABLE:
        assert not stable, verdict  # a witness is a genuine member of the flown set
        w = verdict.witness
        assert w is not None
        if w.delay_samples is not None:
            j = np.diag(np.array(w.inertia).reshape(3, 3))
            h = 1.0 / options["rate"]
            again = max(_lifted_radius(0.25 / j[i], K[i, i], K[i, 3 + i], h, w.delay_samples) for i in range(3))
            assert again == pytest.approx(w.spectral_radius, abs=1e-9)
            assert again > 1.0
    # Every check says what it covers; exact grid checks are labelled necessary.
    for check in verdict.checks:
        assert check.covers
        if check.kind is CheckKind.NECESSARY:
            assert not check.joint
    return verdict.status, stable, rho


@pytest.mark.parametrize(("rate", "jitter", "box"), COMBOS)
def test_stable_gain_every_combination_is_verified(rate: float | None, jitter: bool, box: bool) -> None:
    status, stable, _ = _check_against_reference(STABLE_K, **_options(rate, jitter, box))
    assert stable
    assert status is FlownStatus.VERIFIED


@pytest.mark.parametrize(("rate", "jitter", "box"), COMBOS)
def test_unstable_gain_every_combination_is_unstable(rate: float | None, jitter: bool, box: bool) -> None:
    # 2 Hz for the sampled combinations (the `design --tau 0.5 --rate 2` case), the hot gain otherwise.
    options = _options(None if rate is None else 2.0, jitter, box)
    if jitter and rate is not None:
        options["tau_min"] = 0.0  # d in {0, 1} at 2 Hz
    K = HOT_K if rate is None else DESIGN_K
    status, stable, _ = _check_against_reference(K, **options)
    assert not stable
    assert status is FlownStatus.UNSTABLE


def test_20hz_box_each_part_holds_but_the_flown_loop_is_unstable() -> None:
    # Each part certified separately (sampled at the nominal J; the box in continuous time), jointly unstable.
    for options in ({"rate": 20.0}, {"tolerance": 0.2}):
        status, stable, _ = _check_against_reference(FAST_K, **options)
        assert stable and status is FlownStatus.VERIFIED
    verdict = verify_flown(SC, FAST_K, TAU, rate=20.0, tolerance=0.2, grid=3)
    stable, rho = reference(FAST_K, rate=20.0, tau_min=None, tol=0.2)
    assert not stable and rho == pytest.approx(1.0022330548, abs=1e-8)
    assert verdict.status is FlownStatus.UNSTABLE
    assert verdict.witness is not None and verdict.witness.delay_samples == 10
    assert np.allclose(np.diag(np.array(verdict.witness.inertia).reshape(3, 3)), 0.8 * J0)
    assert verdict.spectral_radius == pytest.approx(rho, abs=1e-9)
    separate = [c for c in verdict.checks if c.kind is CheckKind.LMI and not c.joint]
    assert len(separate) == 2 and all(c.outcome is CheckOutcome.HOLDS for c in separate)
    assert "UNSTABLE" in str(verdict) and "1.00223" in str(verdict)


def test_separate_certificates_only_is_partial_and_names_what_is_not_covered() -> None:
    verdict = verify_flown(SC, EDGE_K, TAU, rate=20.0, tolerance=0.2, grid=3)
    stable, rho = reference(EDGE_K, rate=20.0, tau_min=None, tol=0.2)
    assert stable and rho > 0.999
    assert verdict.status is FlownStatus.PARTIAL
    assert verdict.not_covered and "jointly" in verdict.not_covered[0]
    assert "20 Hz" in verdict.not_covered[0] and "+/-20 %" in verdict.not_covered[0]


def test_jitter_check_of_the_lifted_loop_is_labelled_necessary() -> None:
    verdict = verify_flown(SC, STABLE_K, TAU, rate=20.0, tau_min=0.3, grid=2)
    exact = verdict.checks[0]
    assert exact.kind is CheckKind.NECESSARY and not exact.joint
    assert "every d in [6, 10]" in exact.covers and "not covered" in exact.covers
    assert verdict.status is FlownStatus.VERIFIED  # by the joint LMI, not by the necessary check
    assert any(c.joint and c.kind is CheckKind.LMI and c.outcome is CheckOutcome.HOLDS for c in verdict.checks)


def test_bad_input_names_the_parameter() -> None:
    with pytest.raises(SpecificationError, match="whole number of samples"):
        verify_flown(SC, STABLE_K, 0.5, rate=3.0)
    with pytest.raises(SpecificationError, match="tau_min"):
        verify_flown(SC, STABLE_K, 0.5, tau_min=0.6)
    with pytest.raises(SpecificationError, match="jitter_rate"):
        verify_flown(SC, STABLE_K, 0.5, jitter_rate=0.1)
    with pytest.raises(SpecificationError, match="grid"):
        verify_flown(SC, STABLE_K, 0.5, grid=1)
