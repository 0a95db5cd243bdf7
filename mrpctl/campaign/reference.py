"""Campaigns of the tracking loop: the ``[reference]`` every run flies and its ``[dispersions.reference]``.

A campaign file with a scenario ``[reference]`` table (``type = "inertial" | "slew" | "nadir" | "file"``,
read by the scenario reader) runs the tracking loop on every run (every rule ``hysteretic`` or
``on-predicted``). The reference may be dispersed per run::

    [dispersions.reference]
    slew_angle_deg = [30.0, 180.0]      # a slew's angle (deg), any distribution within (0, 360]
    slew_axis = "sphere"                # a slew's eigenaxis uniform on the unit sphere, per run
    orbit_rate = {distribution = "truncnorm", mean = 1.1e-3, std = 1e-4, low = 5e-4, high = 2e-3}  # nadir, rad/s > 0

``slew_angle_deg`` and ``slew_axis`` apply to ``type = "slew"`` (the drawn angle and axis replace the
base slew's; a slew given by ``target`` keeps the angle and axis computed from it where not dispersed),
``orbit_rate`` to ``type = "nadir"`` (inclination, RAAN and latitude kept). Each run draws from its
own generator, spawn key (case, 2) of the campaign's seed, always in this order: 1 uniform (the slew
angle's quantile), 3 normals (the axis direction), 1 uniform (the orbit rate's quantile); so a run's
reference depends on (seed, case) alone and enabling it moves no other draw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrpctl.campaign.distributions import Distribution, parse_distribution
from mrpctl.errors import SpecificationError
from mrpctl.guidance import CircularOrbit, EigenaxisSlew, GuidanceProfile, NadirPointing

__all__ = [
    "REFERENCE_INPUTS",
    "REFERENCE_KEYS",
    "ReferenceDispersion",
    "parse_reference_dispersion",
    "reference_draws",
    "reference_values",
    "run_reference",
]

#: The keys of ``[dispersions.reference]``.
REFERENCE_KEYS = {"slew_angle_deg", "slew_axis", "orbit_rate"}

#: The per-run reference inputs a tracking campaign stores: (dims after run, units).
REFERENCE_INPUTS: dict[str, tuple[tuple[str, ...], str]] = {
    "slew_angle": ((), "deg"),
    "slew_axis": (("axis",), "1"),
    "orbit_rate": ((), "rad/s"),
}

#: What each key applies to (the [reference] type).
_APPLIES = {"slew_angle_deg": "slew", "slew_axis": "slew", "orbit_rate": "nadir"}


def _kind(reference: GuidanceProfile) -> str:
    if isinstance(reference, EigenaxisSlew):
        return "slew"
    if isinstance(reference, NadirPointing):
        return "nadir"
    return type(reference).__name__


@dataclass(frozen=True)
class ReferenceDispersion:
    """Per-run dispersions of the reference; None (False) keeps the base reference's value.

    Attributes
    ----------
    slew_angle_deg : Distribution or None
        The slew angle Φ (deg), drawn within (0, 360].
    slew_axis : bool
        The slew's eigenaxis uniform on the unit sphere, one per run.
    orbit_rate : Distribution or None
        The circular orbit's rate n (rad/s) of nadir pointing, drawn within (0, ∞).
    """

    slew_angle_deg: Distribution | None = None
    slew_axis: bool = False
    orbit_rate: Distribution | None = None

    def __str__(self) -> str:
        parts = []
        if self.slew_angle_deg is not None:
            parts.append(f"slew angle {self.slew_angle_deg} deg")
        if self.slew_axis:
            parts.append("slew axis uniform on the sphere")
        if self.orbit_rate is not None:
            parts.append(f"orbit rate {self.orbit_rate} rad/s")
        return ", ".join(parts) if parts else "none"


def parse_reference_dispersion(table: dict[str, Any], reference: GuidanceProfile | None) -> ReferenceDispersion:
    """``[dispersions.reference]`` (its keys already checked) against the base ``[reference]``.

    Raises
    ------
    SpecificationError
        Without a ``[reference]``; a key that does not apply to the reference's type; a distribution
        whose draws leave the key's bounds; ``slew_axis`` other than ``"sphere"``. Each names the key.
    """
    if reference is None:
        raise SpecificationError(
            "[dispersions.reference] disperses the reference the loop tracks: the campaign needs a [reference] "
            "table (type = 'slew' or 'nadir'); remove [dispersions.reference] to regulate to the origin"
        )
    kind = _kind(reference)
    for key in sorted(table):
        if _APPLIES[key] != kind:
            raise SpecificationError(
                f"dispersions.reference.{key} applies to a [reference] of type = {_APPLIES[key]!r}, but the "
                f"campaign's reference is a {kind!r} ({reference})"
            )
    angle = None
    if "slew_angle_deg" in table:
        angle = parse_distribution(
            "dispersions.reference.slew_angle_deg", table["slew_angle_deg"], low=0.0, high=360.0, low_open=True
        )
    axis = False
    if "slew_axis" in table:
        if table["slew_axis"] != "sphere":
            raise SpecificationError(
                'dispersions.reference.slew_axis must be "sphere" (an eigenaxis uniform on the unit sphere per run), '
                f"got {table['slew_axis']!r}; give a fixed axis in [reference] axis instead"
            )
        axis = True
    rate = None
    if "orbit_rate" in table:
        rate = parse_distribution("dispersions.reference.orbit_rate", table["orbit_rate"], low=0.0, low_open=True)
    return ReferenceDispersion(slew_angle_deg=angle, slew_axis=axis, orbit_rate=rate)


def reference_draws(seed: int, cases: np.ndarray) -> np.ndarray:
    """(N, 5) variates of each case's reference stream (spawn key (case, 2)): the angle's quantile, the axis's
    3 normals, the orbit rate's quantile."""
    draws = np.empty((len(cases), 5))
    for j, case in enumerate(cases.tolist()):
        generator = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(case, 2)))
        draws[j, 0] = generator.random()
        draws[j, 1:4] = generator.standard_normal(3)
        draws[j, 4] = generator.random()
    return draws


def _unit(vectors: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    fallback = np.zeros(vectors.shape[-1])
    fallback[0] = 1.0
    return np.where(norm > 0.0, vectors / np.where(norm > 0.0, norm, 1.0), fallback)


def reference_values(
    reference: GuidanceProfile | None, dispersion: ReferenceDispersion | None, draws: np.ndarray
) -> dict[str, np.ndarray]:
    """The runs' ``slew_angle`` (deg), ``slew_axis`` and ``orbit_rate`` (rad/s): the drawn value, else the base
    reference's (NaN where the reference has none: no slew, no orbit). A drawn axis is the normalised normals
    (unit to the last bit; the slew normalises it once more, which may move an ulp)."""
    n = len(draws)
    angle, axis, rate = np.full(n, np.nan), np.full((n, 3), np.nan), np.full(n, np.nan)
    dispersion = dispersion if dispersion is not None else ReferenceDispersion()
    if isinstance(reference, EigenaxisSlew):
        base_angle = math.degrees(float(reference.angle or 0.0))
        drawn = dispersion.slew_angle_deg
        angle = np.full(n, base_angle) if drawn is None else drawn.quantile(draws[:, 0])
        axis = _unit(draws[:, 1:4]) if dispersion.slew_axis else np.tile(np.asarray(reference.axis), (n, 1))
    if isinstance(reference, NadirPointing):
        drawn = dispersion.orbit_rate
        rate = np.full(n, reference.orbit.orbit_rate) if drawn is None else drawn.quantile(draws[:, 4])
    return {"slew_angle": angle, "slew_axis": axis, "orbit_rate": rate}


def run_reference(
    reference: GuidanceProfile | None,
    dispersion: ReferenceDispersion | None,
    slew_angle: float,
    slew_axis: np.ndarray,
    orbit_rate: float,
) -> GuidanceProfile | None:
    """The reference a run flies: the base profile itself when it is not dispersed, else the base profile
    with the run's ``slew_angle`` (deg) and ``slew_axis``, or its ``orbit_rate`` (rad/s), each where dispersed
    (the base slew's own angle and axis, not their stored round trip, where not)."""
    if reference is None or dispersion is None:
        return reference
    if isinstance(reference, EigenaxisSlew) and (dispersion.slew_angle_deg is not None or dispersion.slew_axis):
        return EigenaxisSlew(
            start=reference.start,
            rate_limit=reference.rate_limit,
            acceleration_limit=reference.acceleration_limit,
            axis=np.array(slew_axis, dtype=float) if dispersion.slew_axis else reference.axis,
            angle=math.radians(float(slew_angle)) if dispersion.slew_angle_deg is not None else reference.angle,
            t_start=reference.t_start,
        )
    if isinstance(reference, NadirPointing) and dispersion.orbit_rate is not None:
        orbit = reference.orbit
        return NadirPointing(
            CircularOrbit(float(orbit_rate), inclination=orbit.inclination, raan=orbit.raan, latitude=orbit.latitude)
        )
    return reference
