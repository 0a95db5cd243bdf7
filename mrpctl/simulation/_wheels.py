"""``simulate(..., wheels=...)``: one run of the flight loop on a reaction-wheel cluster (compiled engine)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from mrpctl._validation import finite_array, readonly, sealed
from mrpctl.engines.scalar import wheel_engine
from mrpctl.errors import SpecificationError
from mrpctl.flight import FLIGHT_MEMORY_SIZE, Hysteretic
from mrpctl.flight.steering import SteeringLaw
from mrpctl.loop.options import flight_options, flight_structure
from mrpctl.model import wheel_hub_inertia
from mrpctl.simulation.results import SimulationResult, WheelRecord
from mrpctl.switching import SwitchingRule
from mrpctl.wheels import WheelCluster

__all__: list[str] = []

# Bytes per kept sample of the wheel arrays: Ω and u_s as computed and their copies.
_BYTES_PER_WHEEL = 32


def check_wheel_run(wheels: Any, spacecraft: Any, rule: Any, *, actuator: Any, predictor: Any) -> WheelCluster:
    """The wheel cluster of a run, or a SpecificationError naming what to use instead."""
    if not isinstance(wheels, WheelCluster):
        raise SpecificationError(f"wheels must be a mrpctl.wheels.WheelCluster, got {type(wheels).__name__}")
    if predictor is not None:
        raise SpecificationError(
            "wheels: the predictor is not modelled on a wheel cluster; fly the wheels with rule=Hysteretic(delta) "
            "and predictor=None"
        )
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(
            f"wheels: the wheel cluster flies with the controller-side rule only, got rule={type(rule).__name__}; "
            "use rule=Hysteretic(delta) (Hysteretic(0) makes OnCurrent's switching)"
        )
    if actuator is not None:
        raise SpecificationError(
            "actuator: with wheels the torque limits are the wheels' own (WheelCluster torque_limit, speed_limit); "
            "leave actuator=None"
        )
    wheel_hub_inertia(spacecraft, wheels)  # J − Gs diag(Js) Gsᵀ positive definite, or the error naming spin_inertia
    return wheels


def progress_stop(progress: Callable[[int, int], Any] | None, n: int) -> Callable[[int], bool] | None:
    """The engine's ``stop`` of ``simulate``'s ``progress``: reports the samples done, never stops the run itself
    (an exception raised by ``progress`` propagates)."""
    if progress is None:
        return None

    def stop(done: int) -> bool:
        progress(done, n)
        return False

    return stop


def wheel_run_bytes(kept: int, wheels: WheelCluster) -> int:
    """Bytes of the wheel arrays of a run keeping ``kept`` samples."""
    return kept * wheels.count * _BYTES_PER_WHEEL


def run_wheels(
    *,
    spacecraft: Any,
    wheels: WheelCluster,
    rule: SwitchingRule,
    d: int,
    rate: float,
    substeps: int,
    n: int,
    x0: np.ndarray,
    history_rows: np.ndarray,
    gain: np.ndarray,
    keep: int | None,
    disturbance: Any,
    streamed: Any,
    sensor: Any,
    varying: Any,
    stop: Any,
    switch_limit: int,
    law: SteeringLaw | None = None,
) -> Any:
    """Run the wheel engine: (output of the engine, its structure), the caller assembles the result."""
    options, _ = flight_options(rule, None, disturbance, sensor)
    structure = flight_structure(options, sensor)
    found = wheel_engine(
        spacecraft,
        rule,
        d,
        1.0 / rate,
        substeps,
        sensor=structure["sensor"],
        disturbed=structure["disturbed"],
        torque_input=streamed is not None,
        wheels=wheels,
        law=law,
    )
    return found.run(
        x0,
        0.0,
        history_rows,
        gain,
        np.array(rule.parameters()),
        n,
        spacecraft=spacecraft,
        keep_every=keep,
        workspace=found.workspace(n, switches=True),
        switch_limit=switch_limit,
        stop=stop,
        flight_options=options,
        sensor=sensor,
        delay=varying,
        rate=rate,
        **({} if streamed is None else {"disturbance": streamed}),
    )


def wheel_record(
    memory: Any, records: np.ndarray | None, wheels: WheelCluster, *, rate: float, kept: int
) -> WheelRecord:
    """The `WheelRecord` of a run from the wheel sample's memory after the run and its records (``kept`` rows)."""
    count = wheels.count
    part = finite_array("memory", memory)[FLIGHT_MEMORY_SIZE:]
    if records is not None and kept:
        speeds = records[:kept, 13 : 13 + count]  # after the flight sample's (h, σ_c, u_c, σ̃, ω̃)
        motor = records[:kept, 13 + count : 13 + 2 * count]
    else:
        speeds = motor = np.zeros((0, count))
    peak = part[count : 2 * count]
    return WheelRecord(
        cluster=wheels,
        speeds=sealed(np.array(speeds)),
        motor_torque=sealed(np.array(motor)),
        final_speeds=readonly(part[0:count]),
        peak_speed=readonly(peak),
        torque_limited_time=readonly(part[2 * count : 3 * count] / rate),
        speed_limited_time=readonly(part[3 * count : 4 * count] / rate),
        peak_momentum=float(part[4 * count]),
        worst_wheel=int(np.argmax(peak / wheels.speed_limit)),
    )


def wheel_result(result: SimulationResult, output: Any, wheels: WheelCluster, *, rate: float) -> SimulationResult:
    """``result`` with the wheel fields (`WheelRecord`) and the flight fields read from the wheel memory."""
    memory = finite_array("memory", output.memory)
    valid = max(result.samples, 1)
    record = wheel_record(output.memory, output.records, wheels, rate=rate, kept=result.t.shape[0])
    return dataclasses.replace(
        result,
        saturated_fraction=float(memory[5]) / valid,
        peak_command=readonly(memory[6:10]),
        wheels=record,
    )
