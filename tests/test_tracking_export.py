"""The tracking loop as exported CasADi Functions: its reference ports, the manifest, and the same numbers as
``simulate(reference=...)``."""

from __future__ import annotations

import json
import math

import casadi as ca
import numpy as np
import pytest

import mrpctl
from mrpctl import paper
from mrpctl.engines.scalar import tracking_memory
from mrpctl.errors import SpecificationError
from mrpctl.flight import ErrorTime, Hysteretic
from mrpctl.flight.tracking import reference_stream
from mrpctl.loop import closed_loop_functions
from tests.test_tracking import RATE, TAU, X0, slew_rows

pytestmark = pytest.mark.skipif(mrpctl._compile.find_compiler() is None, reason="tracking needs a C compiler")

T_FINAL = 4.0
N = math.floor(T_FINAL * RATE + 1e-9) + 1
D = 5


@pytest.mark.parametrize("error_time", list(ErrorTime))
def test_the_exported_sample_runs_the_simulated_loop(tmp_path, error_time: ErrorTime) -> None:
    rows = slew_rows(N, RATE, math.radians(200.0), 3.0, axis=(-0.6, 0.0, -0.8))
    rule = Hysteretic(0.1)
    result = mrpctl.export(
        paper.SPACECRAFT,
        paper.GAIN,
        tmp_path / "out",
        tau=TAU,
        rule=rule,
        rate=RATE,
        tracking=True,
        error_time=error_time,
        feedforward=True,
        compile=False,
    )
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert list(manifest["functions"]) == list(mrpctl._export.TRACKING_EXPORTED_FUNCTIONS)
    assert manifest["tracking"]["error_time"] == error_time.value and manifest["tracking"]["feedforward"] is True
    assert manifest["tracking"]["reference_ports"]["sample"] == ["reference", "reference_error"]
    inputs = [port["name"] for port in manifest["functions"]["sample"]["inputs"]]
    assert inputs[-2:] == ["reference", "reference_error"]
    assert result.manifest == manifest

    sample = ca.Function.load(str(tmp_path / "out" / "sample.casadi"))
    controller = ca.Function.load(str(tmp_path / "out" / "tracking_controller.casadi"))
    sensor = ca.Function.load(str(tmp_path / "out" / "sensor.casadi"))
    step = ca.Function.load(str(tmp_path / "out" / "step.casadi"))
    simulated = mrpctl.simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        X0,
        tau=TAU,
        rule=rule,
        t_final=T_FINAL,
        rate=RATE,
        reference=rows,
        error_time=error_time,
        feedforward=True,
    )
    closed = closed_loop_functions(paper.SPACECRAFT, paper.GAIN, tau=TAU, rule=rule, rate=RATE, tracking=True)
    assert closed.flight is not None
    memory = np.array(closed.flight.initial_memory(X0, D))
    stream = reference_stream(rows, N, RATE, D, error_time)
    memory[2:5] = tracking_memory(memory[2:5], stream)
    now, error = stream.rows(0, N)
    x, ring, zero = np.array(X0), [], np.zeros(6)
    states, torques, switches = [], [], []
    for k in range(N):
        delayed = X0 if k < D else ring[k - D]
        out = sample(x, memory, delayed, zero, now[k], error[k])
        x_next, memory_next, x_meas, u, switched, measurement = (np.asarray(v).ravel() for v in out[0:6])
        # flight software: the sensor, the tracking controller, the plant: the sample's numbers
        _, measured = (np.asarray(v).ravel() for v in sensor(x, zero))
        pieces = controller(delayed if k >= D else X0, memory[0:5], error[k], rule.delta)
        assert np.array_equal(np.asarray(pieces[0]).ravel(), u)
        assert np.array_equal(np.asarray(step(x_meas, u)).ravel(), x_next)
        assert np.array_equal(measured[3:6], measurement[3:6])
        ring.append(measurement)
        states.append(x_meas)
        torques.append(u)
        if switched:
            switches.append(k)
        x, memory = x_next, memory_next
    np.testing.assert_array_equal(np.array(switches), simulated.switch_indices)
    np.testing.assert_allclose(np.array(states)[:, 0:3], simulated.sigma, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(np.array(torques), simulated.u, rtol=1e-13, atol=1e-12)
    assert len(switches) >= 1


def test_tracking_export_options_are_checked(tmp_path) -> None:
    with pytest.raises(SpecificationError, match="tracking: the tracking loop is the flight loop's"):
        closed_loop_functions(paper.SPACECRAFT, paper.GAIN, tau=TAU, rule=mrpctl.OnCurrent(), rate=RATE, tracking=True)
    with pytest.raises(SpecificationError, match="feedforward: the feedforward terms need the tracking loop"):
        closed_loop_functions(paper.SPACECRAFT, paper.GAIN, tau=TAU, rule=Hysteretic(0.0), rate=RATE, feedforward=True)
    closed = closed_loop_functions(
        paper.SPACECRAFT, paper.GAIN, tau=TAU, rule=Hysteretic(0.0), rate=RATE, tracking=True
    )
    chunk = closed.chunk
    assert chunk.name_in()[-2:] == ["reference", "reference_error"] and chunk.name_out()[-1] == "tracking_error"
    assert chunk.size_in("reference") == (9, D)
