"""A campaign whose runs differ only in their constant torque w (``[dispersions.disturbance]``) makes one
``simulate_batch`` call with one w per run (before: one call per run, ≈ 6× slower); each run still equals
``simulate`` of that run alone with its own w, bit for bit."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrpctl import OnPredicted, Spacecraft, simulate
from mrpctl.campaign import load_campaign, run_inputs
from mrpctl.campaign import simulation as campaign_simulation
from mrpctl.campaign._task import simulate_chunk
from mrpctl.flight import Disturbance, Hysteretic

RATE, T_FINAL, TAU, DELTA = 100.0, 2.0, 0.05, 0.05

CAMPAIGN = f"""
name = "dispersed torque"
count = 6
seed = 5
tau = {TAU}
rate = {RATE}
t_final = {T_FINAL}
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -7.011
k_omega = -16.308
[rule]
type = "hysteretic"
delta = {DELTA}
[flight]
disturbance = [0.5, 0.0, -0.25]
u_max = [30.0, 30.0, 30.0]
[dispersions.attitude]
angle_deg = [150.0, 180.0]
[dispersions.rate]
magnitude = [1.0, 3.0]
[dispersions.disturbance]
magnitude = [1.0, 2.0]
"""


@pytest.mark.parametrize("predicted", [False, True], ids=["hysteretic", "predictor"])
def test_runs_differing_only_in_torque_share_one_call_and_equal_simulate(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, predicted: bool
) -> None:
    text = CAMPAIGN
    if predicted:  # the predictor's runs: one constant torque each too (on the plant, not its model copy)
        text = text.replace(f'type = "hysteretic"\ndelta = {DELTA}', 'type = "on-predicted"') + "[predictor]\n"
    path = tmp_path / "c.toml"
    path.write_text(text, encoding="utf-8")
    spec = load_campaign(path)
    assert (spec.predictor is not None) == predicted
    calls: list[int] = []
    batch = campaign_simulation._batch

    def counted(spacecraft: list[Spacecraft], *args: Any) -> dict[str, np.ndarray]:
        calls.append(len(spacecraft))
        return batch(spacecraft, *args)

    monkeypatch.setattr(campaign_simulation, "_batch", counted)
    out = simulate_chunk(spec, 0, spec.count)
    assert calls == [6]  # one call for the six runs
    w = out["disturbance"]
    assert len({tuple(row) for row in w.tolist()}) == 6  # six different torques
    inputs = run_inputs(spec, 0, spec.count)
    switched = 0
    for i in range(spec.count):
        alone = simulate(  # each run alone, its torque given as the constant Disturbance it is
            Spacecraft(inputs.inertia[i]),
            inputs.gain_scale[i] * spec.base.K,
            inputs.x0[i],
            tau=TAU,
            rule=OnPredicted(1.0) if predicted else Hysteretic(DELTA),
            t_final=T_FINAL,
            rate=RATE,
            predictor=spec.predictor,
            disturbance=Disturbance(w[i]),
            actuator=spec.flight.actuator if spec.flight is not None else None,
            keep_every=None,
        )
        switched += alone.switch_count > 0
        assert alone.switch_count == out["switch_count"][i], i
        for name in ("first_switch_time", "max_sigma", "peak_torque", "settling_time"):
            assert np.float64(getattr(alone, name)).tobytes() == np.float64(out[name][i]).tobytes(), (i, name)
    assert switched >= 2  # tumbles through 180 deg: the switch metrics are compared, not only zeros
