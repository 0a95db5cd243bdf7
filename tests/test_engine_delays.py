"""One compiled library serves every delay d > 0 whose sample code is the same (the drivers take d at run time):
the runs of the shared library at each d against CasADi's virtual machine evaluating the sample of that d, and the
lagged tracking statistics (d an input of the sample) against the lanes' in-sample statistics."""

from __future__ import annotations

import numpy as np

import mrpctl
from mrpctl import paper
from mrpctl.engines import scalar as _engine
from mrpctl.engines.vm import VirtualMachineEngine
from mrpctl.flight import Hysteretic
from mrpctl.switching import DelayAware, OnDelayed

PERIOD = 1e-3  # 1 kHz: d = 5 and d = 50 are tau = 5 ms and 50 ms at the same h


def test_the_delays_of_the_same_code_share_one_library_and_each_run_is_the_virtual_machines() -> None:
    rule = OnDelayed()
    engines = {d: _engine.engine(paper.SPACECRAFT, rule, d, PERIOD, 1) for d in (0, 5, 50)}
    assert engines[5] is not engines[50] and engines[5].compiled.library == engines[50].compiled.library
    assert engines[0].compiled.library != engines[5].compiled.library  # d = 0 reads m_k itself: other code
    held = [_engine.engine(paper.SPACECRAFT, DelayAware(), d, PERIOD, 1).compiled.library for d in (5, 50)]
    assert held[0] != held[1]  # DelayAware's count holds d in its expressions: one library per d
    n, x0 = 400, np.array([0.9, 0.4, 0.2, 0.8, -0.4, 0.2])  # |σ| > 1, turning: the rule switches
    for d in (5, 50):
        compiled = engines[d]
        machine = VirtualMachineEngine(compiled.virtual_machine_sample(), d, compiled.inertia, flight=False)
        outputs = [
            found.run(
                x0, 0.0, x0[None], paper.GAIN, np.array(rule.parameters()), n, spacecraft=paper.SPACECRAFT,
                keep_every=1, workspace=found.workspace(n, switches=True), switch_limit=n,
            )
            for found in (compiled, machine)
        ]  # fmt: skip
        assert outputs[0].samples == outputs[1].samples == n
        assert np.array_equal(outputs[0].measurements, outputs[1].measurements)
        assert np.array_equal(outputs[0].u, outputs[1].u)
        # the statistics but the sample counter (the machine runs whole chunks of d samples, past n)
        assert np.array_equal(outputs[0].stats[1:], outputs[1].stats[1:])
        assert len(outputs[0].switch_indices) >= 1
        assert outputs[0].switch_indices.tolist() == outputs[1].switch_indices.tolist()


def test_the_lagged_statistics_of_one_library_at_two_delays_equal_the_lanes() -> None:
    structure = dict(sensor=False, limited=False, disturbed=False, reference_input=True, feedforward=True)
    libraries = [
        _engine.engine(paper.SPACECRAFT, Hysteretic(0.0), d, PERIOD, 1, lagged_settling=True, **structure)
        for d in (5, 50)
    ]
    assert libraries[0].lagged_settling and libraries[0].compiled.library == libraries[1].compiled.library
    rows = np.zeros((4001, 9))
    rows[:, 2] = np.tan(0.0011 * np.arange(4001) * PERIOD / 4.0)  # nadir pointing: σ_R/N about z
    rows[:, 5] = 0.0011
    for tau in (0.005, 0.05):
        kw = dict(tau=tau, rule=Hysteretic(0.0), t_final=3.0, rate=1.0 / PERIOD, reference=rows, feedforward=True)
        alone = mrpctl.simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, keep_every=None, **kw)
        batch = mrpctl.simulate_batch(paper.SPACECRAFT, paper.GAIN, np.array([paper.INITIAL_STATE] * 2), **kw)
        assert alone.max_sigma > 0.0 and batch.max_sigma[0] == alone.max_sigma
        assert np.nan_to_num(batch.settling_time[0], nan=-1.0) == (alone.settling_time or -1.0)
