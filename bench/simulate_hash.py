"""SHA-256 digests over the result arrays of representative runs (for refactoring without changing a bit).

Run before and after a change to the simulator: no printed hash may move unless a documented fix
changes results.  ``python bench/simulate_hash.py [-v]`` prints one line per part:

* ``simulate``: ~30 runs of the paper's loop (every rule, substeps, histories, batches; the scalar engine);
* ``flight``: the 75 flight-loop runs of ``bench/flight.py hash`` (hysteresis, actuator, disturbance,
  sensor, jitter, a full inertia, three batches);
* ``predictor``: the predictor controller (exact and wrong model, actuator limits, a batch);
* ``lanes``: metrics-only ``simulate_batch`` calls that go to the lane engine (rules, flight options);
* ``campaign``: one chunk of each shipped example campaign (``examples/campaigns/*.toml``).
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

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


def predictor_cases() -> list[tuple[str, object]]:
    from mrpctl.design import pd_gains
    from mrpctl.flight import ActuatorModel
    from mrpctl.predictor import OnPredicted, Predictor, perturbed_spacecraft

    fast = pd_gains(SC, zeta=1.0, omega_n=12.85).K
    heavy = perturbed_spacecraft(SC, 0.05)
    out: list[tuple[str, object]] = []
    for name, plant, options in (
        ("exact", SC, {}),
        ("heavy plant", heavy, {}),
        ("limits", heavy, {"actuator": ActuatorModel([200.0, 200.0, 200.0])}),
    ):
        run = simulate(
            plant,
            fast,
            X0,
            tau=0.5,
            t_final=5.0,
            rate=200.0,
            rule=OnPredicted(1.0),
            predictor=Predictor(model=SC),
            **options,
        )
        out.append((f"predictor {name}", run))
    states = X0 + 0.01 * np.random.default_rng(7).standard_normal((6, 6))
    batch = simulate_batch(
        heavy, fast, states, tau=0.5, t_final=5.0, rate=200.0, rule=OnPredicted(1.0), predictor=Predictor(model=SC)
    )
    out.append(("predictor batch", batch))
    return out


def lane_cases() -> list[tuple[str, object]]:
    from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, SensorModel

    rng = np.random.default_rng(11)
    states = np.hstack((0.55 * rng.uniform(-1, 1, (40, 3)), 0.4 * rng.standard_normal((40, 3))))
    out: list[tuple[str, object]] = []
    for rule in (OnDelayed(), DelayAware(), BoundaryLayer(0.05), Hysteretic(0.1)):
        batch = simulate_batch(SC, paper.GAIN, states, tau=0.05, t_final=8.0, rate=200.0, rule=rule)
        out.append((f"lanes {rule}", batch))
    flown = simulate_batch(
        SC,
        paper.GAIN,
        states,
        tau=0.5,
        t_final=8.0,
        rate=200.0,
        rule=Hysteretic(0.05),
        actuator=ActuatorModel([20.0, 25.0, 30.0]),
        disturbance=Disturbance([1e-2, -2e-2, 5e-3]),
        sensor=SensorModel(attitude_noise=0.01, rate_noise=1e-4, seed=3),
        delay=DelayModel.jitter(0.4, 0.5, seed=2),
    )
    out.append(("lanes flown", flown))
    return out


def campaign_digest(verbose: bool) -> str:
    from mrpctl.campaign._task import simulate_chunk
    from mrpctl.campaign.spec import load_campaign

    total = hashlib.sha256()
    folder = Path(__file__).resolve().parent.parent / "examples" / "campaigns"
    for path in sorted(folder.glob("*.toml")):
        spec = load_campaign(path)
        chunk = simulate_chunk(spec, 0, min(8, spec.count), threads=2)
        part = hashlib.sha256()
        for key in sorted(chunk):
            part.update(key.encode())
            part.update(np.ascontiguousarray(chunk[key]).tobytes())
        one = part.hexdigest()[:16]
        total.update(one.encode())
        if verbose:
            print(f"{one}  campaign {path.stem}")
    return total.hexdigest()


def digest(results: list[tuple[str, object]], verbose: bool) -> str:
    total = hashlib.sha256()
    for name, result in results:
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
    return total.hexdigest()


def main() -> None:
    verbose = "-v" in sys.argv
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from flight import flight_hash  # bench/flight.py

    print("simulate ", digest(cases(), verbose))
    print("flight   ", flight_hash())
    print("predictor", digest(predictor_cases(), verbose))
    print("lanes    ", digest(lane_cases(), verbose))
    print("campaign ", campaign_digest(verbose))


if __name__ == "__main__":
    main()
