"""``mrpctl verify`` of a tracking scenario: the tracking-error loop linearised about its reference motion.

What is checked, per linearisation ([`mrpctl.design.tracking`][mrpctl.design.tracking]): the exact delay margin
of ẋ = A x + A_d x(t − τ) and whether τ lies inside it, the Bessel-Legendre LMI certificate at τ for each of
``--orders`` (at least one must certify), and, at the scenario's rate, the exact stability of the sampled loop
(zero-order hold, d = τ · rate samples, the lifted companion matrix block by block). Nadir pointing is
linearised with and without the gravity-gradient stiffness (the engines fly it without; an orbit has it), and
both must hold. An eigenaxis slew is linearised about rest (the error dynamics about a constant reference,
which hold before and after the slew).

What is not: the slew's time-varying profile, a file reference (time-varying: no linearisation), the error
formed against the reference of *now* (``error_time = "current"``) on a turning reference, the predictor's
tracking loop, the loop-as-flown models of the scenario (actuator limits, sensor noise, disturbance, delay
jitter, the [uncertainty] inertia box) and an inertia whose products leave part of the reference's torque
unsupplied (x = 0 is then not the loop's equilibrium). Each of these is named in the output and makes the
verdict NOT VERIFIED, never a silent pass.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrpctl.cli.common import NOT_VERIFIED, flown_options_given, print_json
from mrpctl.clock import delay_samples
from mrpctl.design.lmi import criterion_name
from mrpctl.design.sampled import MAX_LIFTED_SIZE
from mrpctl.design.tracking import TrackingLinearization, tracking_linearization
from mrpctl.errors import SpecificationError
from mrpctl.flight.tracking import ErrorTime
from mrpctl.guidance import EigenaxisSlew, InertialPointing, NadirPointing, reference_samples
from mrpctl.mrp import to_dcm
from mrpctl.scenario import Scenario

__all__ = ["check_tracking_options", "verify_tracking"]


@dataclass(frozen=True)
class _Check:
    """One linearisation's checks: exact margin, LMI certificates, sampled-data stability (None: not run)."""

    name: str
    loop: TrackingLinearization
    margin: float
    stable_at_tau: bool
    certificates: tuple[tuple[int, str, bool], ...]
    delay_samples: int
    spectral_radius: float | None
    sampled: str

    @property
    def certified(self) -> bool:
        """At least one LMI order certifies τ (τ = 0 needs none)."""
        return not self.certificates or any(certified for _, _, certified in self.certificates)

    @property
    def sampled_stable(self) -> bool:
        return self.spectral_radius is not None and self.spectral_radius < 1.0

    @property
    def verified(self) -> bool:
        return self.stable_at_tau and self.certified and self.sampled_stable

    @property
    def status(self) -> str:
        """VERIFIED; UNSTABLE (τ outside the exact margin, or the sampled loop unstable); NOT CERTIFIED (stable,
        but no LMI order proves it); NOT CHECKED (the sampled loop too large to lift)."""
        if self.verified:
            return "VERIFIED"
        if not self.stable_at_tau or (self.spectral_radius is not None and not self.sampled_stable):
            return "UNSTABLE"
        return "NOT CHECKED" if self.spectral_radius is None else "NOT CERTIFIED"


def check_tracking_options(args: argparse.Namespace) -> None:
    """Refuse the loop-as-flown options of ``verify``: they build regulation certificates (the per-axis
    jitter interval, the inertia polytope) that a tracking loop does not have."""
    given = flown_options_given(args)
    if given:
        raise SpecificationError(
            f"{given[0]} does not apply to a tracking scenario ([reference]): its verdict is the linearised tracking "
            "loop's at the scenario's rate; leave out the option"
        )


def _turning(reference: Any) -> bool:
    """Whether the reference turns (ω_R ≠ 0 at some time): anything but inertial pointing."""
    return not isinstance(reference, InertialPointing)


def _uncovered(scenario: Scenario, loops: list[TrackingLinearization]) -> list[str]:
    """What the tracking verdict does not cover for this scenario (each one makes it NOT VERIFIED)."""
    reference = scenario.reference
    missing = []
    if isinstance(reference, EigenaxisSlew):
        missing.append(
            "the slew's time-varying profile: the loop is linearised about rest (before and after the slew), "
            "not along the slew (simulate it)"
        )
    elif not isinstance(reference, InertialPointing | NadirPointing):
        missing.append(
            f"a {type(reference).__name__} is time-varying: no linearisation about a constant reference motion "
            "covers it (simulate it)"
        )
    error_time = scenario.error_time
    if error_time is None and scenario.predictor is not None:
        error_time = ErrorTime.CURRENT  # simulate's default with a predictor
    if error_time is ErrorTime.CURRENT and _turning(reference):
        missing.append(
            "the error formed against the reference of now (error_time = current) on a turning reference: its "
            "linear part differs by the rotation of R over tau and is not modelled"
        )
    if scenario.predictor is not None:
        missing.append("the predictor's tracking loop: not linearised here")
    flown = sorted(scenario.flight_options) + (["uncertainty"] if scenario.uncertainty is not None else [])
    if flown:
        missing.append(
            "the loop-as-flown models (" + ", ".join(flown) + ") of the tracking loop: not certified, the checks "
            "are the idealised tracking loop's"
        )
    unbalanced = max((float(np.linalg.norm(loop.unbalanced_torque)) for loop in loops), default=0.0)
    if unbalanced > 0.0:
        missing.append(
            f"the law leaves {unbalanced:.3g} N m of the reference's torque unsupplied (products of inertia in "
            "the reference axes): x = 0 is not the loop's equilibrium, the checks are about x = 0"
        )
    return missing


def _check(name: str, loop: TrackingLinearization, tau: float, rate: float, orders: list[int]) -> _Check:
    margin = loop.delay_margin()
    stable = margin.is_stable(tau) if tau > 0 else bool(margin.stable_without_delay)
    certificates = []
    for order in orders if tau > 0 else []:
        certificate = loop.certify(tau, order=order)
        certificates.append((order, certificate.status.name, certificate.certified))
    d = delay_samples(tau, rate)
    try:
        sampled = loop.sampled_stability(1.0 / rate, delay_samples=d)
    except SpecificationError:  # the lifted companion is refused above MAX_LIFTED_SIZE rows
        text = (
            f"sampled loop h = {1.0 / rate:.6g} s, d = {d}: not checked (its lifted companion would exceed "
            f"{MAX_LIFTED_SIZE} rows; a lower rate or a shorter delay fits)"
        )
        return _Check(name, loop, margin.margin, stable, tuple(certificates), d, None, text)
    return _Check(name, loop, margin.margin, stable, tuple(certificates), d, sampled.spectral_radius, str(sampled))


def _checks(scenario: Scenario, tau: float, orders: list[int]) -> list[_Check]:
    """The linearisations the reference has (none for a file reference), each checked."""
    reference = scenario.reference
    feedforward = scenario.feedforward
    if isinstance(reference, NadirPointing):
        return [
            _check(
                label,
                tracking_linearization(
                    scenario.spacecraft, scenario.K, reference, gravity_gradient=gravity, feedforward=feedforward
                ),
                tau,
                scenario.rate,
                orders,
            )
            for gravity, label in ((True, "nadir pointing with the gravity gradient"), (False, "nadir pointing"))
        ]
    if isinstance(reference, InertialPointing | EigenaxisSlew):
        label = "about rest (the slew's end points)" if isinstance(reference, EigenaxisSlew) else "inertial pointing"
        loop = tracking_linearization(scenario.spacecraft, scenario.K, None, feedforward=feedforward)
        return [_check(label, loop, tau, scenario.rate, orders)]
    return []


def _local_note(scenario: Scenario) -> str:
    """What a linearisation does not say: the loop far from its reference, with this scenario's initial error."""
    reference = scenario.reference
    start = ""
    if reference is not None:
        row = reference_samples(reference, 1, scenario.rate)[0]
        relative = to_dcm(scenario.sigma0) @ to_dcm(row[:3]).T  # [BR] = [BN][NR]
        cosine = min(1.0, max(-1.0, (float(np.trace(relative)) - 1.0) / 2.0))
        start = f"; this scenario starts {math.degrees(math.acos(cosine)):.3g} deg from its reference"
    return (
        "the nonlinear loop away from the reference motion (the checks are of its linearisation; no region of "
        f"attraction is certified here{start}): simulate the scenario, or run a campaign of it"
    )


def verify_tracking(args: argparse.Namespace, scenario: Scenario, tau: float) -> int:
    """Print (or write as JSON) the tracking scenario's verdict; the exit code is 0 when VERIFIED (every check
    holds and nothing is left uncovered), else NOT_VERIFIED."""
    reference = scenario.reference
    checks = _checks(scenario, tau, args.orders)
    missing = _uncovered(scenario, [check.loop for check in checks])
    missing += [f"{check.name}: the {check.sampled}" for check in checks if check.spectral_radius is None]
    verified = bool(checks) and not missing and all(check.verified for check in checks)
    code = 0 if verified else NOT_VERIFIED
    if args.json:
        print_json(
            {
                "tau": tau,
                "rate": scenario.rate,
                "reference": str(reference),
                "error_time": None if scenario.error_time is None else scenario.error_time.value,
                "feedforward": scenario.feedforward,
                "checks": [
                    {
                        "loop": check.name,
                        "linearisation": str(check.loop),
                        "exact_delay_margin": check.margin,
                        "stable_at_tau": check.stable_at_tau,
                        "criteria": [
                            {"criterion": criterion_name(order), "order": order, "status": status, "certified": ok}
                            for order, status, ok in check.certificates
                        ],
                        "certified": check.certified,
                        "delay_samples": check.delay_samples,
                        "spectral_radius": check.spectral_radius,
                        "sampled": check.sampled,
                        "sampled_stable": check.sampled_stable,
                        "status": check.status,
                        "verified": check.verified,
                    }
                    for check in checks
                ],
                "not_covered": missing,
                "local": _local_note(scenario),
                "verified": verified,
                "exit_code": code,
            }
        )
        return code
    print(f"tracking scenario {scenario.name}: {reference}")
    print(f"tau = {tau:g} s at {scenario.rate:g} Hz, feedforward {'on' if scenario.feedforward else 'off'}")
    for check in checks:
        print(f"{check.name}: {check.loop}")
        if math.isinf(check.margin):
            margin = "infinite (stable for every delay)"
        else:
            margin = f"{check.margin:.9g} s" if check.margin > 0 else "none (unstable without delay)"
        print(f"  exact delay margin {margin}; stable at tau = {tau:g} s: {'yes' if check.stable_at_tau else 'NO'}")
        for order, status, _ in check.certificates:
            print(f"  {criterion_name(order):<24} at tau: {status}")
        print(f"  {check.sampled}")
        print(f"  {check.status}")
    for item in missing:
        print(f"not covered: {item}")
    print(f"not checked (the verdict is local): {_local_note(scenario)}")
    word = "VERIFIED" if verified else "NOT VERIFIED"
    if any(check.status == "UNSTABLE" for check in checks):
        word += " (UNSTABLE)"
    scope = "the checks above, each about its constant reference motion" if checks else "nothing could be checked"
    print(f"tracking verdict: {word} (exit {code}): {scope}")
    return code
