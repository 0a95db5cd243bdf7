"""One convention for a relative inertia error e everywhere: the plant against the model, J = (1 + e) J_m."""

from __future__ import annotations

import inspect
import re
import tomllib

import numpy as np

from mrpctl import paper
from mrpctl._predictor_study import StudyRow
from mrpctl.predictor import (
    MarginInterval,
    PredictorDesign,
    inertia_mismatch_margin,
    perturbed_spacecraft,
    synthesize_predictor_pd,
)
from mrpctl.scenario import parse_scenario, predictor_model

#: J_plant = (1 + e) J_model, J = (1 + e) J_m, or J = S J_m S: the plant on the left
CONVENTION = re.compile(r"J(_plant)? = \(1 \+ e\) J_(m|model)\b|J = S J_m S")


def test_every_docstring_of_an_inertia_error_states_the_one_convention() -> None:
    for thing in (
        perturbed_spacecraft,
        inertia_mismatch_margin,
        MarginInterval,
        PredictorDesign,
        synthesize_predictor_pd,
        predictor_model,
        StudyRow,
    ):
        doc = re.sub(r"\s+", " ", inspect.getdoc(thing) or "")
        assert CONVENTION.search(doc), thing.__name__
        assert "J_m = (1 + e) J" not in doc, thing.__name__  # the other direction, used before for the scenario key


def test_the_scenario_key_is_the_inverse_of_perturbed_spacecraft() -> None:
    plant = paper.SPACECRAFT
    for e in (0.1, -0.3, 2.0):
        model = predictor_model(plant, inertia_error=e)
        np.testing.assert_allclose(perturbed_spacecraft(model, e).inertia, plant.inertia, rtol=1e-15)
    errors = [0.1, -0.05, 0.2]
    model = predictor_model(plant, inertia_error=errors)
    back = model
    for axis, e in enumerate(errors):
        back = perturbed_spacecraft(back, e, axis=axis)
    np.testing.assert_allclose(back.inertia, plant.inertia, rtol=1e-15)
    assert np.array_equal(predictor_model(plant, inertia_error=0.0).inertia, plant.inertia)  # e = 0: the same bits


def test_a_scenario_with_e_is_the_margins_plant_with_e() -> None:
    text = """
tau = 0.5
t_final = 1.0
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -70.11
k_omega = -163.08
[initial]
sigma = [0.1, 0.0, 0.0]
omega = [0.0, 0.0, 0.0]
[rule]
type = "on-predicted"
[predictor]
inertia_error = 0.1
"""
    scenario = parse_scenario(tomllib.loads(text))
    assert scenario.predictor is not None
    # the margin's e = +0.1 is the plant 10 % heavier than the model: the scenario's plant against its model
    np.testing.assert_allclose(
        perturbed_spacecraft(scenario.predictor.model, 0.1).inertia, scenario.spacecraft.inertia, rtol=1e-15
    )
