"""``mrpctl verify`` of a predictor scenario: the predictor loop linearised about the origin.

What is checked ([`mrpctl.predictor`][mrpctl.predictor]): the exact stability of the sampled predictor loop
x̂_{k+1} = (Φ + Γ_m K) x̂_k + Φ^d (Γ − Γ_m) K x̂_{k−d} at the scenario's rate, with the scenario's spacecraft as the
plant and the predictor's model as J_m ([`predictor_stability`][mrpctl.predictor.predictor_stability]). Both
predictor forms ([`PredictorForm`][mrpctl.predictor.PredictorForm]) linearise to this one loop, so the check is
the same for either. Reported beside it, not part of the verdict: the inertia mismatch margin of the gain about
the model ([`inertia_mismatch_margin`][mrpctl.predictor.inertia_mismatch_margin], uniform and per axis).

What is not: the loop-as-flown models of the scenario (actuator limits, sensor noise, disturbance, the
[uncertainty] inertia box), which each make the verdict NOT VERIFIED when the scenario has them; and, always, the
nonlinear loop away from the origin (large rotations, the switching rule on σ̂, the linear form's prediction
error on skew-axis motion): the verdict is local. The plain delayed loop's certificates (the delay margin, the
LMI criteria, the loop-as-flown set) are of the loop without the predictor and are not run.
"""

from __future__ import annotations

import argparse
from typing import Any

from mrpctl.cli.common import NOT_VERIFIED, flown_options_given, print_json
from mrpctl.clock import delay_samples
from mrpctl.errors import SpecificationError
from mrpctl.predictor import StabilityStatus, inertia_mismatch_margin, predictor_stability
from mrpctl.scenario import Scenario

__all__ = ["check_predictor_options", "verify_predictor"]


def check_predictor_options(args: argparse.Namespace) -> None:
    """Refuse the loop-as-flown options of ``verify``: they build certificates of the plain delayed loop (the
    jitter interval, the inertia polytope, the sampled PD loop) that the predictor loop does not have."""
    given = flown_options_given(args)
    if given:
        raise SpecificationError(
            f"{given[0]} does not apply to a predictor scenario ([predictor]): its verdict is the linearised "
            "predictor loop's at the scenario's rate; leave out the option"
        )


def _uncovered(scenario: Scenario) -> list[str]:
    """What the predictor verdict does not cover for this scenario (each one makes it NOT VERIFIED)."""
    flown = sorted(name for name in scenario.flight_options if name != "predictor")
    flown += ["uncertainty"] if scenario.uncertainty is not None else []
    if not flown:
        return []
    return [
        "the loop-as-flown models (" + ", ".join(flown) + ") of the predictor loop: not certified, the check is the "
        "linearised predictor loop's without them"
    ]


_LOCAL = (
    "the nonlinear loop away from the origin (large rotations, the switching rule on sigma_hat, and for the linear "
    "form its prediction error on skew-axis motion; design/predictor.md): simulate the scenario, or run a campaign"
)


def verify_predictor(args: argparse.Namespace, scenario: Scenario, tau: float) -> int:
    """Print (or write as JSON) the predictor scenario's verdict; the exit code is 0 when VERIFIED (the sampled
    predictor loop is shown stable and nothing is left uncovered), else NOT_VERIFIED."""
    predictor = scenario.predictor
    assert predictor is not None
    d = delay_samples(tau, scenario.rate)
    stability = predictor_stability(predictor.model, scenario.K, tau, plant=scenario.spacecraft, rate=scenario.rate)
    margin = inertia_mismatch_margin(predictor.model, scenario.K, tau, rate=scenario.rate)
    missing = _uncovered(scenario)
    verified = stability.status is StabilityStatus.STABLE and not missing
    code = 0 if verified else NOT_VERIFIED
    covers = (
        f"the predictor loop linearised about the origin (the FSA prediction; either predictor form), sampled at "
        f"{scenario.rate:g} Hz with zero-order hold and d = {d} samples, plant {scenario.spacecraft}, model "
        f"{predictor.model}"
    )
    if args.json:
        document: dict[str, Any] = {
            "tau": tau,
            "rate": scenario.rate,
            "delay_samples": d,
            "predictor_form": predictor.form.value,
            "covers": covers,
            "status": stability.status.value if stability.status is not None else None,
            "method": stability.method.value,
            "stable": stability.stable,
            "mismatch_margin": {
                "symmetric": margin.symmetric,
                "uniform": [margin.uniform.lower, margin.uniform.upper],
                "per_axis": [[m.lower, m.upper] for m in margin.per_axis],
            },
            "not_covered": missing,
            "local": _LOCAL,
            "verified": verified,
            "exit_code": code,
        }
        print_json(document)
        return code
    print(f"predictor scenario {scenario.name}: {predictor}")
    print(f"covers: {covers}")
    print(f"  {stability}")
    print(f"  {margin}".replace("\n", "\n  "))
    for item in missing:
        print(f"not covered: {item}")
    print(f"not checked (the verdict is local): {_LOCAL}")
    print(
        "not run: the plain delayed loop's delay margin, LMI criteria and loop-as-flown certificates (they are of the "
        "loop without the predictor)"
    )
    word = "VERIFIED" if verified else "NOT VERIFIED"
    if stability.status is StabilityStatus.UNSTABLE:
        word += " (UNSTABLE)"
    elif stability.status is StabilityStatus.UNRESOLVED:
        word += " (UNRESOLVED: a root on the unit circle to within rounding)"
    print(f"predictor verdict: {word} (exit {code})")
    return code
