"""A SHA-256 over the result arrays of ~30 representative simulations (for refactoring without changing a bit).

Run before and after a change to the simulator: the printed hash must not move unless a
documented fix changes results.  ``python bench/simulate_hash.py [-v]``.
"""

from __future__ import annotations

import hashlib
import sys

import numpy as np

import mrpctl
from mrpctl import paper
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed

simulate = mrpctl.simulate if callable(mrpctl.simulate) else mrpctl.simulate.simulate  # type: ignore[attr-defined]
simulate_batch = mrpctl.simulate_batch

SC = paper.SPACECRAFT
GENERAL = Spacecraft(np.array([[140.0, 4.0, -2.0], [4.0, 100.0, 3.0], [-2.0, 3.0, 80.0]]))
X0 = np.array(paper.INITIAL_STATE, dtype=float)
X1 = np.array([0.5, 0.2, -0.1, 0.05, 0.0, 0.02])
RULES = [NoSwitching(), OnCurrent(), OnDelayed(), BoundaryLayer(0.005), DelayAware(), DelayAware(1.1)]
UNSTABLE = np.hstack((np.zeros((3, 3)), 2000.0 * np.eye(3)))


def cases() -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = []
    for rule in RULES:
        for tau in (0.0, 0.02):
            out.append((f"{rule} tau={tau}", simulate(SC, paper.GAIN, X0, tau=tau, rule=rule, t_final=8.0)))
    for rule in (OnDelayed(), DelayAware()):
        out.append((f"{rule} s2", simulate(SC, paper.GAIN, X0, tau=0.05, rule=rule, t_final=6.0, substeps=2)))
        out.append(
            (f"{rule} zero", simulate(SC, paper.GAIN, X0, tau=0.05, rule=rule, t_final=6.0, history="zero-input"))
        )
        past = np.linspace(-0.3, 0.4, 20 * 6).reshape(20, 6)
        out.append((f"{rule} array", simulate(SC, paper.GAIN, X1, tau=0.02, rule=rule, t_final=3.0, history=past)))
    out.append(("general inertia", simulate(GENERAL, paper.GAIN, X0, tau=0.013, rule=OnDelayed(), t_final=5.0)))
    out.append(("rate 250", simulate(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=20.0, rate=250.0)))
    out.append(("diverging d0", simulate(SC, UNSTABLE, X0, tau=0.0, rule=OnCurrent(), t_final=30.0)))
    out.append(("diverging d5", simulate(SC, UNSTABLE, X1, tau=0.005, rule=OnDelayed(), t_final=30.0)))
    out.append(("paper 60 s", simulate(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=60.0)))
    states = np.array([X0, X1, -X1, [0.9, 0.3, 0.1, 0.1, -0.05, 0.02]])
    for trajectories in (False, True):
        out.append(
            (
                f"batch traj={trajectories}",
                simulate_batch(
                    SC,
                    paper.GAIN,
                    states,
                    tau=[0.0, 0.02, 0.02, 0.05],
                    rule=[BoundaryLayer(0.05), BoundaryLayer(0.2), BoundaryLayer(0.01), BoundaryLayer(0.1)],
                    t_final=4.0,
                    trajectories=trajectories,
                    threads=2,
                ),
            )
        )
    out.append(
        (
            "batch diverging",
            simulate_batch(SC, [paper.GAIN, UNSTABLE], X1, tau=0.01, rule=OnDelayed(), t_final=10.0, substeps=2),
        )
    )
    return out


RUN_FIELDS = ("t", "sigma", "omega", "u", "switch_indices", "switch_times", "sign_flips")
BATCH_FIELDS = (
    "switch_count",
    "first_switch_time",
    "last_switch_time",
    "sign_flips",
    "settling_time",
    "converged",
    "diverged",
    "max_sigma",
)


def digest_run(run: object) -> list[bytes]:
    parts = [np.ascontiguousarray(getattr(run, name)).tobytes() for name in RUN_FIELDS]
    parts.append(repr((run.max_sigma, run.settling_time, run.diverged)).encode())  # type: ignore[attr-defined]
    return parts


def main() -> None:
    verbose = "-v" in sys.argv
    total = hashlib.sha256()
    for name, result in cases():
        parts: list[bytes] = []
        if hasattr(result, "runs"):
            parts += [np.ascontiguousarray(getattr(result, f)).tobytes() for f in BATCH_FIELDS]
            for run in result.runs or ():
                parts += digest_run(run)
        else:
            parts += digest_run(result)
        one = hashlib.sha256(b"".join(parts)).hexdigest()[:16]
        total.update(one.encode())
        if verbose:
            print(f"{one}  {name}")
    print(total.hexdigest())


if __name__ == "__main__":
    main()
