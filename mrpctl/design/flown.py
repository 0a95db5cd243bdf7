"""Joint verdicts on the loop as flown: sampled *and* jittery *and* uncertain together.

The flown set is the one a scenario describes: the spacecraft with a gain K, the measurement delay τ,
optionally the sample rate (zero-order hold, d = τ·rate samples), a jitter interval (the delay of each
measurement anywhere in [τ_min, τ]; held, the plant sees τ(t) ∈ [τ_min, τ + h)) and an inertia box
([inertia_polytope][mrpctl.design.polytope.inertia_polytope]).
[verify_flown][mrpctl.design.flown.verify_flown] answers for that set as a whole, with two kinds of evidence,
each naming exactly what it covers:

- **exact checks**: the lifted discrete-time loop ([sampled_stability][mrpctl.design.sampled.sampled_stability])
  or, unsampled, the exact constant-delay stability intervals
  ([delay_margin][mrpctl.design.margin.delay_margin]), at every member of a finite set of the flown loop
  (vertices and a grid of the inertia box, the whole-sample delays of the jitter interval). On a
  single member (no box, no jitter) this is a proof; on a grid it is a necessary check, not a proof.
  An instability found at any member is a witness that the flown set is not stable.
- **LMI certificates**: one Lyapunov-Krasovskii functional common to every vertex of the J⁻¹ box
  ([certify_polytope][mrpctl.design.polytope.certify_polytope] with the delay interval: the sawtooth
  τ(t) ∈ [d h, (d+1) h] of the sampled loop, or the jitter interval with the rate unknown, or the
  constant delay with the vertex-dependent functional). Every block of the interval criterion is
  affine in the plant or a quadratic form of it with a positive semidefinite weight, so the vertex
  LMIs hold on the convex hull: a joint certificate covers the whole flown set.

The status ([FlownStatus][mrpctl.design.flown.FlownStatus]) is VERIFIED only when one check covers the whole
flown set jointly; when only separate certificates hold (say, the nominal sampled loop and the continuous-time
box) it is PARTIAL and ``FlownVerdict.not_covered`` says what no
certificate covers; an exact check that finds an instability makes it UNSTABLE with the witness.
"""

from __future__ import annotations

import enum
import itertools
import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import integer, nonnegative_scalar, positive_scalar
from mrpctl.design.interval import DelayRate, certify_interval, rate_value
from mrpctl.design.lmi import CertificateStatus
from mrpctl.design.loop import linearized_loop
from mrpctl.design.margin import delay_margin
from mrpctl.design.polytope import InertiaPolytope, certify_polytope, inertia_polytope
from mrpctl.design.sampled import MAX_LIFTED_SIZE, certify_sampled, sampled_stability, spacecraft_axes
from mrpctl.errors import InertiaWarning, SpecificationError
from mrpctl.model import gain_matrix
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "UNRESOLVED_BAND",
    "CheckKind",
    "CheckOutcome",
    "FlownCheck",
    "FlownStatus",
    "FlownVerdict",
    "Witness",
    "verify_flown",
]

#: A lifted spectral radius within this distance of 1 is neither a proof nor a witness (unresolved).
UNRESOLVED_BAND = 1e-9


class FlownStatus(enum.Enum):
    """The overall verdict on the flown set."""

    #: One certificate (LMI, or an exact check on a single member) covers the whole flown set.
    VERIFIED = "verified: one certificate covers the whole loop as flown"
    #: Certificates hold for parts of the flown set separately, none for the whole set jointly.
    PARTIAL = "partial: certificates hold separately, none covers the loop as flown jointly"
    #: No certificate holds; the exact checks found no instability at the points they checked.
    NOT_CERTIFIED = "not certified: no certificate holds (no instability found either)"
    #: An exact check found a member of the flown set unstable (see the witness).
    UNSTABLE = "unstable: an exact check found a flown loop unstable"


class CheckKind(enum.Enum):
    """What a check proves."""

    #: Exact stability of the one loop it names (a proof for exactly that loop).
    EXACT = "exact"
    #: Exact at finitely many members of the set: an instability is a witness, stability is necessary only.
    NECESSARY = "exact at grid points (necessary, not a proof)"
    #: An LMI certificate (a proof for what it covers).
    LMI = "LMI certificate"


class CheckOutcome(enum.Enum):
    """The answer of one check."""

    HOLDS = "holds"
    #: Exact: a checked member is unstable. LMI: not certified (no evidence of instability).
    FAILS = "fails"
    #: Exact: the spectral radius is within UNRESOLVED_BAND of 1; LMI: the solver gave no usable answer.
    UNRESOLVED = "unresolved"
    #: Not run (the reason is in ``detail``).
    SKIPPED = "skipped"


@dataclass(frozen=True)
class Witness:
    """A member of the flown set found unstable by an exact check.

    Attributes
    ----------
    inertia : tuple of float
        The inertia's 9 entries (row major, kg m²).
    delay : float
        The delay (s): constant delay, or d·h of the lifted loop.
    delay_samples : int or None
        d of the lifted loop (None when not sampled).
    spectral_radius : float
        Lifted spectral radius (nan for the continuous-time loop).
    text : str
    """

    inertia: tuple[float, ...]
    delay: float
    delay_samples: int | None
    spectral_radius: float
    text: str

    def __str__(self) -> str:
        return self.text


@dataclass(frozen=True)
class FlownCheck:
    """One check of [verify_flown][mrpctl.design.flown.verify_flown].

    Attributes
    ----------
    name : str
    kind : CheckKind
    outcome : CheckOutcome
    covers : str
        Exactly what the check covers (and, for grid checks, how dense the grid is).
    joint : bool
        True when it covers the whole flown set (an EXACT or LMI check that holds is then a proof of it).
    detail : str
    spectral_radius : float
        Largest lifted spectral radius met (nan when no lifted loop was checked).
    witness : Witness or None
    """

    name: str
    kind: CheckKind
    outcome: CheckOutcome
    covers: str
    joint: bool
    detail: str
    spectral_radius: float = math.nan
    witness: Witness | None = None

    def __str__(self) -> str:
        scope = "the whole flown set" if self.joint else "part of the flown set"
        head = f"{self.name} [{self.kind.value}; {scope}]: {self.outcome.value.upper()}"
        lines = [head, f"    covers: {self.covers}"]
        if self.detail:
            lines.append("    " + self.detail.replace("\n", "\n    "))
        if self.witness is not None:
            lines.append(f"    witness: {self.witness}")
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class FlownVerdict:
    """Result of [verify_flown][mrpctl.design.flown.verify_flown].

    Attributes
    ----------
    status : FlownStatus
    flown : str
        The flown set in words.
    checks : tuple of FlownCheck
    not_covered : tuple of str
        What of the flown set no holding certificate covers (empty when VERIFIED).
    witness : Witness or None
        The instability found (UNSTABLE only).
    spectral_radius : float
        The largest lifted spectral radius of the exact checks (nan when the loop is not sampled).
    """

    status: FlownStatus
    flown: str
    checks: tuple[FlownCheck, ...] = field(repr=False)
    not_covered: tuple[str, ...]
    witness: Witness | None
    spectral_radius: float

    @property
    def verified(self) -> bool:
        return self.status is FlownStatus.VERIFIED

    def __str__(self) -> str:
        lines = [f"loop as flown: {self.flown}", f"joint verdict: {self.status.name} ({self.status.value})"]
        if self.witness is not None:
            lines.append(f"  witness: {self.witness}")
        lines += [f"  NOT covered jointly: {item}" for item in self.not_covered]
        lines += ["  " + str(check).replace("\n", "\n  ") for check in self.checks]
        return "\n".join(lines)


# ------------------------------------------------------------------------------------------------
# The flown set


@dataclass(frozen=True)
class _Flown:
    spacecraft: Spacecraft
    K: np.ndarray
    tau: float
    rate: float | None
    samples: int
    tau_min: float | None
    jitter_rate: DelayRate
    polytope: InertiaPolytope | None

    @property
    def period(self) -> float:
        return math.nan if self.rate is None else 1.0 / self.rate

    @property
    def min_samples(self) -> int:
        if self.rate is None or self.tau_min is None:
            return self.samples
        return min(self.samples, math.ceil(self.tau_min * self.rate - 1e-9))

    def describe(self) -> str:
        parts = [f"J = {_inertia_text(np.array(self.spacecraft.inertia))} kg m^2"]
        if self.rate is None:
            parts.append("continuous time")
        else:
            parts.append(f"sampled at {self.rate:g} Hz with zero-order hold")
        if self.tau_min is None:
            parts.append(f"delay {self.tau:g} s" + ("" if self.rate is None else f" (d = {self.samples} samples)"))
        elif self.rate is None:
            parts.append(f"delay jittering in [{self.tau_min:g}, {self.tau:g}] s ({self.jitter_rate})")
        else:
            parts.append(
                f"delay jittering over whole samples d in [{self.min_samples}, {self.samples}] "
                f"(tau in [{self.tau_min:g}, {self.tau:g}] s; {self.jitter_rate})"
            )
        if self.polytope is not None:
            p = self.polytope
            box = f"inertia box +/-{100 * p.tolerance:g} % per axis"
            if p.product_bound > 0.0:
                box += f", |J_ij| <= {p.product_bound:g} kg m^2"
            parts.append(box)
        return "; ".join(parts)


def _inertia_text(j: np.ndarray) -> str:
    if np.all(j == np.diag(np.diag(j))):
        return "diag(" + ", ".join(f"{v:.6g}" for v in np.diag(j)) + ")"
    return "[" + "; ".join(" ".join(f"{v:.6g}" for v in row) for row in j) + "]"


def _members(flown: _Flown, grid: int) -> tuple[list[np.ndarray], str, bool]:
    """The inertias the exact checks use, what they are, and whether they are the whole inertia set."""
    j0 = np.array(flown.spacecraft.inertia, dtype=float)
    poly = flown.polytope
    if poly is None or (poly.tolerance == 0.0 and poly.product_bound == 0.0):
        return [j0], "the nominal inertia", True
    tol = poly.tolerance
    d0 = np.diag(j0)
    k = gain_matrix(flown.K)
    diagonal_gain = np.all(k[:, :3] == np.diag(np.diag(k[:, :3]))) and np.all(k[:, 3:] == np.diag(np.diag(k[:, 3:])))
    if poly.product_bound == 0.0 and diagonal_gain:
        scales = np.linspace(1.0 - tol, 1.0 + tol, grid)
        what = (
            f"{grid} inertias per axis evenly spaced over J_ii in [(1 - {tol:g}) J0_ii, (1 + {tol:g}) J0_ii], "
            "ends included; the loop splits per axis, so this covers every combination of those per-axis "
            f"values (all 8 vertices of the box and {grid}^3 grid points)"
        )
        return [np.diag(s * d0) for s in scales], what, False
    q = min(grid, 3)
    diag_values = [np.linspace((1 - tol) * d0[i], (1 + tol) * d0[i], q) for i in range(3)]
    p = poly.product_bound
    off = np.linspace(-p, p, q) if p > 0.0 else np.zeros(1)
    out = []
    for a, b, c in itertools.product(*diag_values):
        for e01, e02, e12 in itertools.product(off, off, off):
            j = np.array([[a, e01, e02], [e01, b, e12], [e02, e12, c]])
            eig = np.linalg.eigvalsh(j)
            if eig[0] > 0 and eig[2] <= eig[0] + eig[1]:
                out.append(j)
    what = f"{q} values per diagonal entry (ends included)" + (
        f" x {q} values per product of inertia in [-{p:g}, {p:g}]" if p > 0 else ""
    )
    return out, f"{len(out)} physical inertias of the set: {what}", False


def _member(flown: _Flown, j: np.ndarray) -> Spacecraft:
    """The spacecraft of one member inertia of the set, without repeating the nominal's InertiaWarning.

    The caller's spacecraft already warned once if its inertia is not physically realisable; the set's
    members are points of the analysis, not new input, so they do not warn again (the nominal itself is
    the caller's object).
    """
    if np.array_equal(j, np.asarray(flown.spacecraft.inertia, dtype=float)):
        return flown.spacecraft
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InertiaWarning)
        return Spacecraft(j)


def _delay_list(flown: _Flown, points: int) -> tuple[list[int], str]:
    """The whole-sample delays the lifted check uses (all of them when at most ``points``)."""
    lo, hi = flown.min_samples, flown.samples
    if lo == hi:
        return [hi], f"d = {hi}"
    if hi - lo + 1 <= points:
        return list(range(lo, hi + 1)), f"every d in [{lo}, {hi}]"
    picks = sorted({round(v) for v in np.linspace(lo, hi, points)})
    return picks, f"{len(picks)} of the {hi - lo + 1} delays in [{lo}, {hi}] samples (ends included): {picks}"


# ------------------------------------------------------------------------------------------------
# Exact checks


def _lifted_check(flown: _Flown, grid: int, delay_points: int) -> FlownCheck:
    members, what, whole_box = _members(flown, grid)
    delays, delay_what = _delay_list(flown, delay_points)
    h = flown.period
    joint = whole_box and flown.tau_min is None
    kind = CheckKind.EXACT if joint else CheckKind.NECESSARY
    name = "exact lifted loop"
    covers = f"the lifted discrete-time loop at {flown.rate:g} Hz, {delay_what}, at {what}"
    if flown.tau_min is not None:
        covers += (
            "; each delay held constant (a jittering delay switches between these loops: not covered by this check)"
        )
    cache: dict[bytes, float] = {}
    worst, worst_at = -math.inf, None
    skipped = 0
    for j in members:
        axes = spacecraft_axes(_member(flown, j), flown.K)
        for d in delays:
            rho = -math.inf
            for a, b, k in axes:
                if a.shape[0] * (d + 1) > MAX_LIFTED_SIZE:
                    skipped += 1
                    continue
                key = a.tobytes() + b.tobytes() + k.tobytes() + str(d).encode()
                if key not in cache:
                    cache[key] = sampled_stability(a, b, k, h, delay_samples=d).spectral_radius
                rho = max(rho, cache[key])
            if rho > worst:
                worst, worst_at = rho, (j, d)
    if skipped:
        return FlownCheck(
            name,
            kind,
            CheckOutcome.SKIPPED,
            covers,
            False,
            f"{skipped} lifted loop(s) above MAX_LIFTED_SIZE = {MAX_LIFTED_SIZE} rows were not checked",
            worst if worst > -math.inf else math.nan,
        )
    assert worst_at is not None
    j, d = worst_at
    at = f"J = {_inertia_text(j)} kg m^2, d = {d} samples ({d * h:g} s) at {flown.rate:g} Hz"
    detail = f"largest spectral radius {worst:.9f} at {at}"
    if worst >= 1.0 + UNRESOLVED_BAND:
        witness = Witness(tuple(map(float, j.ravel())), d * h, d, worst, f"{at}: spectral radius {worst:.9f} > 1")
        return FlownCheck(name, kind, CheckOutcome.FAILS, covers, joint, detail, worst, witness)
    if worst > 1.0 - UNRESOLVED_BAND:
        detail += f" (within {UNRESOLVED_BAND:g} of 1: unresolved)"
        return FlownCheck(name, kind, CheckOutcome.UNRESOLVED, covers, joint, detail, worst)
    return FlownCheck(name, kind, CheckOutcome.HOLDS, covers, joint, detail, worst)


def _continuous_check(flown: _Flown, grid: int) -> FlownCheck:
    members, what, whole_box = _members(flown, grid)
    lo = flown.tau if flown.tau_min is None else flown.tau_min
    hi = flown.tau
    joint = whole_box and flown.tau_min is None
    kind = CheckKind.EXACT if joint else CheckKind.NECESSARY
    name = "exact constant-delay loop"
    if flown.tau_min is None:
        covers = f"the continuous-time loop with the constant delay {hi:g} s at {what}"
    else:
        covers = (
            f"the continuous-time loop with every constant delay in [{lo:g}, {hi:g}] s at {what} "
            "(a time-varying delay is not covered by this check)"
        )
    smallest = math.inf
    for j in members:
        loop = linearized_loop(_member(flown, j), flown.K)
        margin = delay_margin(loop.A, loop.A_d)
        inside = [(a, b) for a, b in margin.stable_intervals if (a < lo or (a == 0.0 and lo == 0.0)) and hi < b]
        if not inside:
            # the first delay of [lo, hi] that no stable interval contains
            bad = lo
            for a, b in sorted(margin.stable_intervals):
                if (a < bad or (a == 0.0 and bad == 0.0)) and bad < b:
                    bad = b
            bad = min(bad, hi)
            at = f"J = {_inertia_text(j)} kg m^2, constant delay {bad:.6g} s"
            witness = Witness(
                tuple(map(float, j.ravel())), bad, None, math.nan, f"{at}: not stable (exact {margin.reason})"
            )
            return FlownCheck(
                name, kind, CheckOutcome.FAILS, covers, joint, str(margin).split("\n")[0], math.nan, witness
            )
        smallest = min(smallest, inside[0][1])
    detail = (
        "every checked loop is stable over the delays checked "
        f"(smallest upper end of its stable interval {smallest:.6g} s)"
    )
    return FlownCheck(name, kind, CheckOutcome.HOLDS, covers, joint, detail)


# ------------------------------------------------------------------------------------------------
# LMI certificates


def _lmi_outcome(status: CertificateStatus) -> CheckOutcome:
    if status is CertificateStatus.CERTIFIED:
        return CheckOutcome.HOLDS
    if status is CertificateStatus.SOLVER_FAILED:
        return CheckOutcome.UNRESOLVED
    return CheckOutcome.FAILS


def _worst(statuses: list[CertificateStatus]) -> CertificateStatus:
    if any(s is CertificateStatus.SOLVER_FAILED for s in statuses):
        return CertificateStatus.SOLVER_FAILED
    if any(s is CertificateStatus.NOT_CERTIFIED for s in statuses):
        return CertificateStatus.NOT_CERTIFIED
    return CertificateStatus.CERTIFIED


def _delay_interval(flown: _Flown, *, sampled: bool, jitter: bool) -> tuple[str, float | None, float, DelayRate | None]:
    """(words, tau_min, tau_max, rate) of the delay the input-delay certificate sees (tau_min None: constant)."""
    h = flown.period
    if sampled and jitter:
        assert flown.tau_min is not None
        return (
            f"tau(t) in [{flown.tau_min:g}, {flown.tau + h:g}] s ({flown.jitter_rate}; the jittered sample delay plus "
            "the hold)",
            flown.tau_min,
            flown.tau + h,
            flown.jitter_rate,
        )
    if sampled:
        d = flown.samples
        return (
            f"the sampled-data sawtooth tau(t) in [{d * h:g}, {(d + 1) * h:g}] s (d = {d}, rate 1, any sampling "
            f"intervals <= {h:g} s)",
            d * h,
            (d + 1) * h,
            DelayRate.sawtooth(),
        )
    if jitter:
        assert flown.tau_min is not None
        return (
            f"tau(t) in [{flown.tau_min:g}, {flown.tau:g}] s ({flown.jitter_rate}), continuous time",
            flown.tau_min,
            flown.tau,
            flown.jitter_rate,
        )
    return f"the constant delay {flown.tau:g} s, continuous time", None, flown.tau, None


def _lmi_check(flown: _Flown, *, sampled: bool, jitter: bool, box: bool, order: int | None, joint: bool) -> FlownCheck:
    delay_words, lo, hi, rate = _delay_interval(flown, sampled=sampled, jitter=jitter)
    poly = flown.polytope if box else None
    where = "the nominal inertia" if poly is None else f"every inertia of the J^-1 box ({len(poly.vertices)} vertices)"
    if sampled and not jitter:
        n = 0 if order is None else order
    elif lo is not None:
        n = 1 if order is None else order
    else:
        n = 2 if order is None else order
    covers = f"{delay_words}, at {where}"
    name = "joint LMI certificate" if joint else "separate LMI certificate"
    if hi <= 0.0:
        return FlownCheck(name, CheckKind.LMI, CheckOutcome.SKIPPED, covers, False, "no delay: nothing to certify")
    if poly is not None:
        if lo is None:
            cert = certify_polytope(poly, flown.K, hi, order=n)
        else:
            cert = certify_polytope(poly, flown.K, hi, order=n, tau_min=lo, delay_rate=rate)
        status = cert.status
        detail = str(cert)
    else:
        if sampled and not jitter:
            parts: list[Any] = [
                certify_sampled(a, b, k, flown.period, delay_samples=flown.samples, order=n)
                for a, b, k in spacecraft_axes(flown.spacecraft, flown.K)
            ]
            status = _worst([c.status for c in parts])
            detail = "\n".join(str(c) for c in parts)
        elif lo is not None:
            loop = linearized_loop(flown.spacecraft, flown.K)
            pairs = loop.axes if loop.split else ((loop.A, loop.A_d),)
            parts = [certify_interval(a, a_d, hi, tau_min=lo, delay_rate=rate, order=n) for a, a_d in pairs]
            status = _worst([c.status for c in parts])
            detail = "\n".join(str(c) for c in parts)
        else:
            cert1 = linearized_loop(flown.spacecraft, flown.K).certify(hi, order=n)
            status, detail = cert1.status, str(cert1)
    return FlownCheck(name, CheckKind.LMI, _lmi_outcome(status), covers, joint, detail)


# ------------------------------------------------------------------------------------------------


def verify_flown(
    spacecraft: Spacecraft,
    K: Any,
    tau: float,
    *,
    rate: float | None = None,
    tau_min: float | None = None,
    jitter_rate: DelayRate | float | None = None,
    tolerance: float | None = None,
    product_bound: float = 0.0,
    polytope: InertiaPolytope | None = None,
    order: int | None = None,
    grid: int = 5,
    delay_points: int = 5,
) -> FlownVerdict:
    """The joint verdict on the loop as flown (sampled, jittery and uncertain together).

    Parameters
    ----------
    spacecraft : Spacecraft
        The nominal spacecraft.
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).
    tau : float
        Measurement delay (s), >= 0; with ``rate`` a whole number d = τ·rate of samples.
    rate : float, optional
        Sample rate (Hz) of the zero-order-held loop; None: continuous time.
    tau_min : float, optional
        Lower end of the jitter interval [tau_min, tau] (s); with ``rate`` the flown delays are the
        whole samples in it.
    jitter_rate : DelayRate or float, optional
        Bound on the delay's rate (None: unknown, the flown delay jumps from sample to sample).
    tolerance, product_bound : float, optional
        The inertia box of [inertia_polytope][mrpctl.design.polytope.inertia_polytope] (or give ``polytope``).
    polytope : InertiaPolytope, optional
        The inertia set itself (instead of ``tolerance``).
    order : int, optional
        Bessel-Legendre order of the LMI certificates (default 0 for the sampled sawtooth, 1 for an
        interval delay, 2 for a constant delay).
    grid : int, optional
        Inertias per axis of the exact checks, ends included (default 5; at least 2).
    delay_points : int, optional
        Whole-sample delays of the jitter interval the lifted check takes, ends included (default 5;
        every delay when there are at most that many).

    Returns
    -------
    FlownVerdict
    """
    sc = check_spacecraft(spacecraft)
    k = gain_matrix(K)
    tau = nonnegative_scalar("tau", tau)
    grid = integer("grid", grid, minimum=2)
    delay_points = integer("delay_points", delay_points, minimum=2)
    hz = None if rate is None else positive_scalar("rate", rate)
    d = 0
    if hz is not None:
        d = round(tau * hz)
        if abs(tau * hz - d) > 1e-9 * max(1.0, tau * hz):
            raise SpecificationError(f"tau * rate must be a whole number of samples, got {tau * hz!r}")
    lo = None
    if tau_min is not None:
        lo = nonnegative_scalar("tau_min", tau_min)
        if not lo < tau:
            raise SpecificationError(f"tau_min must be < tau = {tau:g} s, got {lo:g}")
    elif jitter_rate is not None:
        raise SpecificationError("jitter_rate applies only with tau_min (the jitter interval)")
    if polytope is not None and tolerance is not None:
        raise SpecificationError("give either tolerance or polytope, not both")
    poly = polytope
    if poly is not None and not isinstance(poly, InertiaPolytope):
        raise SpecificationError(f"polytope must be an InertiaPolytope, got {type(poly).__name__}")
    if poly is None and tolerance is not None:
        poly = inertia_polytope(sc, tolerance, product_bound=product_bound)
    elif poly is None and product_bound:
        raise SpecificationError("product_bound applies only with tolerance")
    if poly is not None and poly.tolerance == 0.0 and poly.product_bound == 0.0:
        poly = None
    flown = _Flown(sc, k, tau, hz, d, lo, rate_value(jitter_rate), poly)

    sampled, jitter, box = hz is not None, lo is not None, poly is not None
    checks: list[FlownCheck] = []
    checks.append(_lifted_check(flown, grid, delay_points) if sampled else _continuous_check(flown, grid))
    joint = _lmi_check(flown, sampled=sampled, jitter=jitter, box=box, order=order, joint=True)
    checks.append(joint)
    components = [name for name, on in (("sampling", sampled), ("jitter", jitter), ("inertia box", box)) if on]
    if joint.outcome is not CheckOutcome.HOLDS and len(components) > 1:
        # Each part of the flown set alone, the others at their idealised values.
        for part in components:
            checks.append(
                _lmi_check(
                    flown,
                    sampled=part == "sampling",
                    jitter=part == "jitter",
                    box=part == "inertia box",
                    order=order,
                    joint=False,
                )
            )

    failed = [c for c in checks if c.kind is not CheckKind.LMI and c.outcome is CheckOutcome.FAILS]
    spectral = max((c.spectral_radius for c in checks if not math.isnan(c.spectral_radius)), default=math.nan)
    whole = [c for c in checks if c.joint and c.outcome is CheckOutcome.HOLDS]
    separate = [c for c in checks if c.kind is CheckKind.LMI and not c.joint and c.outcome is CheckOutcome.HOLDS]
    not_covered: list[str] = []
    if failed:
        status, witness = FlownStatus.UNSTABLE, failed[0].witness
    else:
        witness = None
        if whole:
            status = FlownStatus.VERIFIED
        else:
            status = FlownStatus.PARTIAL if separate else FlownStatus.NOT_CERTIFIED
            not_covered.append(f"{flown.describe()}: no certificate covers this set jointly")
            for c in checks:
                if c.kind is CheckKind.LMI and not c.joint and c.outcome is not CheckOutcome.HOLDS:
                    not_covered.append(f"{c.covers}: {c.outcome.value}")
    return FlownVerdict(status, flown.describe(), tuple(checks), tuple(not_covered), witness, spectral)
