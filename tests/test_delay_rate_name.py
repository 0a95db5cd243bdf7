"""One word per meaning: ``rate`` is a measurement rate (Hz); the bound on a delay's rate dτ/dt is ``delay_rate``
(its old name ``rate`` still works, with a DeprecationWarning)."""

from __future__ import annotations

import inspect
import warnings

import numpy as np
import pytest

import mrpctl.design as design
from mrpctl.design import certify_interval
from mrpctl.design._common import NOT_GIVEN
from mrpctl.design.robust import delay_set
from mrpctl.errors import SpecificationError

A = np.array([[-2.0, 0.0], [0.0, -0.9]])
AD = np.array([[-1.0, 0.0], [-1.0, -1.0]])
RENAMED = ("certify_interval", "max_certified_interval_delay", "certify_polytope", "synthesize_robust_pd",
           "synthesize_lmi", "synthesize_pd")  # fmt: skip


def test_the_delay_rate_keyword_and_its_deprecated_name_give_the_same_certificate() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new name warns nothing
        new = certify_interval(A, AD, 2.0, delay_rate=0.5)
    with pytest.warns(DeprecationWarning, match="use delay_rate="):
        old = certify_interval(A, AD, 2.0, rate=0.5)
    assert new.certified and old.certified and new.delay_rate == old.delay_rate
    with pytest.raises(SpecificationError, match="not both"), pytest.warns(DeprecationWarning):
        certify_interval(A, AD, 2.0, rate=0.5, delay_rate=0.5)
    with pytest.raises(SpecificationError, match="delay_rate applies only with tau_min"):
        delay_set(0.5, delay_rate=0.1)


def test_no_design_function_takes_rate_for_a_delay_rate() -> None:
    for name in (*RENAMED, "delay_set"):
        parameters = inspect.signature(delay_set if name == "delay_set" else getattr(design, name)).parameters
        assert "delay_rate" in parameters, name
        assert parameters["rate"].default is NOT_GIVEN, name  # only the deprecated alias
    for name in design.__all__:
        thing = getattr(design, name)
        if callable(thing) and not isinstance(thing, type) and name not in RENAMED:
            parameters = inspect.signature(thing).parameters
            if "rate" in parameters:  # any other `rate` of the design package is a sample rate in Hz
                doc = inspect.getdoc(thing) or ""
                assert "Hz" in doc.split("rate :", 1)[-1].split("\n", 2)[1], name


def test_a_body_rate_is_body_rate() -> None:
    from mrpctl.scenario import tumbling_states

    new = tumbling_states(5, seed=2, body_rate=(1.0, 2.0))
    with pytest.warns(DeprecationWarning, match="use body_rate="):
        old = tumbling_states(5, seed=2, rate=(1.0, 2.0))
    assert np.array_equal(new, old)
    with pytest.raises(SpecificationError, match="body_rate"):
        tumbling_states(5, body_rate=(2.0, 1.0))


def test_delay_rates_and_orbit_rates_are_named_for_what_they_are() -> None:
    """``rate`` is a sample rate in Hz: the delay's rate bound is ``delay_rate`` on every certificate and delay
    set, the orbit's rate ``orbit_rate``; the old attribute names still read, with a DeprecationWarning."""
    from mrpctl.design import max_certified_interval_delay
    from mrpctl.guidance import CircularOrbit, NadirPointing

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cert = certify_interval(A, AD, 2.0, delay_rate=0.5)
        search = max_certified_interval_delay(A, AD, delay_rate=0.5, tau_min=0.0)
        delays = delay_set(0.5, tau_min=0.1, delay_rate=0.2)
        orbit = CircularOrbit(orbit_rate=1.1e-3)
        nadir = NadirPointing(orbit)
        assert str(cert.delay_rate) in str(cert) and str(search.delay_rate) in str(search)
        assert (delays.delay_rate.lower, delays.delay_rate.upper) == (-0.2, 0.2)
        assert (orbit.orbit_rate, nadir.orbit_rate, CircularOrbit(1.1e-3).orbit_rate) == (1.1e-3,) * 3
    for owner, value in ((cert, cert.delay_rate), (search, search.delay_rate), (delays, delays.delay_rate)):
        with pytest.warns(DeprecationWarning, match=r"\.rate is deprecated: use \.delay_rate"):
            assert owner.rate is value
    for owner in (orbit, nadir):
        with pytest.warns(DeprecationWarning, match=r"\.rate is deprecated: use \.orbit_rate"):
            assert owner.rate == 1.1e-3
    with pytest.warns(DeprecationWarning, match="use orbit_rate="):
        assert CircularOrbit(rate=1.1e-3).orbit_rate == 1.1e-3
    with pytest.raises(SpecificationError, match="not both"), pytest.warns(DeprecationWarning):
        CircularOrbit(1.1e-3, rate=1.1e-3)
    with pytest.raises(SpecificationError, match="orbit_rate must be > 0"):
        CircularOrbit(orbit_rate=0.0)


def test_the_body_rate_dispersion_is_omega_and_its_old_name_still_reads() -> None:
    """A campaign's body-rate dispersion is ``[dispersions.omega]``; ``[dispersions.rate]`` reads the same with a
    DeprecationWarning, and both at once is refused."""
    import tomllib

    from mrpctl.campaign.sampling import run_inputs
    from mrpctl.campaign.spec import parse_campaign

    text = """
count = 6
seed = 3
tau = 0.5
rate = 100.0
t_final = 1.0
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -7.011
k_omega = -16.308
[rule]
type = "hysteretic"
delta = 0.1
[dispersions.{name}]
magnitude = [0.0, 0.1]
"""
    new = parse_campaign(tomllib.loads(text.format(name="omega")))
    with pytest.warns(DeprecationWarning, match=r"\[dispersions.omega\]"):
        old = parse_campaign(tomllib.loads(text.format(name="rate")))
    assert new.omega is not None and new.omega == old.omega
    assert np.array_equal(run_inputs(new, 0).omega0, run_inputs(old, 0).omega0)
    assert np.any(run_inputs(new, 0).omega0 != 0.0)
    with pytest.warns(DeprecationWarning, match=r"use \.omega"):
        assert old.rate == new.omega
    both = tomllib.loads(text.format(name="omega") + "[dispersions.rate]\nmagnitude = [0.0, 0.1]\n")
    with pytest.raises(SpecificationError, match="not both"):
        parse_campaign(both)
