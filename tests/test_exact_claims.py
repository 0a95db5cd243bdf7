"""What the docs say about runs that equal other runs, stated as measured and tested exactly so.

`Hysteretic(0)` against `OnCurrent` (README): σ and ω bit for bit, the torques equal under `==` with bits
that differ only in the sign of zero. The predictor with an exact model against the undelayed `OnCurrent`
run (design/predictor.md): equal up to rounding, not bit for bit, within the bounds the page states.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from mrpctl import OnCurrent, OnPredicted, Predictor, paper, simulate
from mrpctl.flight import Hysteretic

ROOT = Path(__file__).resolve().parents[1]
X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])


def _bits(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64).view(np.uint64)


def _flat(text: str) -> str:
    return re.sub(r"\s+", " ", text)


def test_the_predictor_page_states_the_exact_model_bounds_it_is_tested_against() -> None:
    page = _flat((ROOT / "design" / "predictor.md").read_text(encoding="utf-8"))
    assert "**bit-identical**" not in page
    claim = page.split("With an exact model the predictor run is the undelayed `OnCurrent` run from x0", 1)[1][:400]
    assert claim.startswith(" up to rounding, not bit for bit")
    assert "σ and ω within 1e-15" in claim and "torques within 1e-13 N m" in claim


def test_exact_model_predictor_equals_the_undelayed_run_within_the_stated_bounds() -> None:
    sc = paper.SPACECRAFT
    common = dict(t_final=3.5, rate=1000.0)
    pred = simulate(sc, paper.GAIN, X0, tau=0.5, rule=OnPredicted(), predictor=Predictor(model=sc), **common)
    undelayed = simulate(sc, paper.GAIN, X0, tau=0.0, rule=OnCurrent(), **common)
    assert pred.switch_indices.tolist() == undelayed.switch_indices.tolist() == [438]
    assert np.max(np.abs(pred.sigma - undelayed.sigma)) <= 1e-15
    assert np.max(np.abs(pred.omega - undelayed.omega)) <= 1e-15
    assert np.max(np.abs(pred.u - undelayed.u)) <= 1e-13
    assert np.max(np.abs(undelayed.u)) > 80.0  # the bound is against an 84 N m peak


def test_the_readme_states_hysteretic_zero_as_measured() -> None:
    readme = _flat((ROOT / "README.md").read_text(encoding="utf-8"))
    assert "gives `OnCurrent`'s σ and ω bit for bit and its torques equal under `==`" in readme
    assert "differ only in the sign of zero" in readme
    common = dict(tau=0.5, t_final=60.0)
    plant_side = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=OnCurrent(), **common)
    flight = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(0.0), **common)
    assert np.array_equal(_bits(flight.sigma), _bits(plant_side.sigma))
    assert np.array_equal(_bits(flight.omega), _bits(plant_side.omega))
    assert np.array_equal(flight.u, plant_side.u)
    differ = _bits(flight.u) != _bits(plant_side.u)
    assert np.all(flight.u[differ] == 0.0)
    count = int(np.sum(differ))
    assert f"{count:,}".replace(",", " ") + " of the " in readme  # the README's count of -0 / +0 entries
