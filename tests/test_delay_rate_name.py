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
    assert new.certified and old.certified and new.rate == old.rate
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
