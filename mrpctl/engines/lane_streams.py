"""The stream rows of the lane engine, one slice at a time: the sensor noise (drawn by ``noise.c``), the
torque of each sample and, for a tracking sample, the reference rows, shared by the lanes of a batch or each
lane's own (a nonzero j of lane l at its offset + j W + l), in the layout ``LaneEngine`` streams them."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from mrpctl.engines.scalar import noise_rows
from mrpctl.flight import NOISE_SIZE, DelayModel, Disturbance, SensorModel, newest_arrived_slice
from mrpctl.flight.tracking import REFERENCE_WIDTH, ReferenceStream

__all__ = [
    "lane_flight_rows",
    "lane_newest_arrived",
    "lane_reference_rows",
    "lane_torque_rows",
    "noise_and_torque_rows",
    "tracking_rows",
]


def noise_and_torque_rows(
    sensor: SensorModel | None, noise_columns: int, disturbance: Disturbance, rate: float, k0: int, k1: int
) -> np.ndarray:
    """The stream rows of a slice: the noise (``noise_columns``: NOISE_SIZE, zero without a noisy sensor;
    0 for a sample without a sensor) and the torque w_k, side by side."""
    rows = np.zeros((k1 - k0, noise_columns + 3))
    if sensor is not None:
        rows[:, :noise_columns] = noise_rows(sensor, k0, k1)  # drawn by noise.c
    rows[:, noise_columns:] = disturbance.samples(k0, k1, rate)
    return rows


def tracking_rows(
    sensor: SensorModel | None,
    noise_columns: int,
    disturbance: Disturbance | None,
    reference: ReferenceStream,
    rate: float,
    k0: int,
    k1: int,
) -> np.ndarray:
    """The stream rows of a slice of a tracking sample: the noise and the torque as in `noise_and_torque_rows`
    (the torque's 3 columns only with one), then the reference at t_k (9) and at the error time (9)."""
    torque_columns = 0 if disturbance is None else 3
    start = noise_columns + torque_columns
    rows = np.zeros((k1 - k0, start + 2 * REFERENCE_WIDTH))
    if sensor is not None:
        rows[:, :noise_columns] = noise_rows(sensor, k0, k1)  # drawn by noise.c
    if disturbance is not None:
        rows[:, noise_columns:start] = disturbance.samples(k0, k1, rate)
    now, error = reference.rows(k0, k1)
    rows[:, start : start + REFERENCE_WIDTH] = now
    rows[:, start + REFERENCE_WIDTH :] = error
    return rows


def lane_reference_rows(
    sensor: SensorModel | None,
    noise_columns: int,
    shared_torque: Disturbance | None,
    torques: Sequence[Disturbance] | None,
    references: Sequence[ReferenceStream],
    rate: float,
    width: int,
    k0: int,
    k1: int,
    runs: np.ndarray,
) -> np.ndarray:
    """The stream rows of a slice for the W ``runs`` of a batch of a tracking sample with per-lane references:
    the shared noise and the shared torque (if any), then the per-lane torques (if any, 3 W), then each lane's
    reference at t_k (9 W) and at the error time (9 W) (nonzero j of lane l at its offset + j W + l)."""
    shared = noise_columns + (3 if shared_torque is not None else 0)
    per_lane = (3 if torques is not None else 0) + 2 * REFERENCE_WIDTH
    rows = np.zeros((k1 - k0, shared + per_lane * width))
    if sensor is not None:
        rows[:, :noise_columns] = noise_rows(sensor, k0, k1)  # drawn by noise.c
    if shared_torque is not None:
        rows[:, noise_columns:shared] = shared_torque.samples(k0, k1, rate)
    offset = shared
    if torques is not None:
        lanes = np.zeros((k1 - k0, 3, width))
        for lane, run in enumerate(runs):
            lanes[:, :, lane] = torques[int(run)].samples(k0, k1, rate)
        rows[:, offset : offset + 3 * width] = lanes.reshape(k1 - k0, 3 * width)
        offset += 3 * width
    now = np.zeros((k1 - k0, REFERENCE_WIDTH, width))
    error = np.zeros((k1 - k0, REFERENCE_WIDTH, width))
    for lane, run in enumerate(runs):
        now[:, :, lane], error[:, :, lane] = references[int(run)].rows(k0, k1)
    rows[:, offset : offset + REFERENCE_WIDTH * width] = now.reshape(k1 - k0, REFERENCE_WIDTH * width)
    rows[:, offset + REFERENCE_WIDTH * width :] = error.reshape(k1 - k0, REFERENCE_WIDTH * width)
    return rows


def lane_torque_rows(
    sensor: SensorModel | None,
    noise_columns: int,
    torques: Sequence[Disturbance],
    rate: float,
    width: int,
    k0: int,
    k1: int,
    runs: np.ndarray,
) -> np.ndarray:
    """The stream rows of a slice for the W ``runs`` of a batch: the shared noise (``noise_columns``, as in
    `noise_and_torque_rows`), then each lane's own torque w_k (nonzero j of lane l at noise_columns + j W + l)."""
    rows = np.zeros((k1 - k0, noise_columns + 3 * width))
    if sensor is not None:
        rows[:, :noise_columns] = noise_rows(sensor, k0, k1)  # drawn by noise.c
    lanes = np.empty((k1 - k0, 3, width))
    for lane, run in enumerate(runs):
        lanes[:, :, lane] = torques[int(run)].samples(k0, k1, rate)
    rows[:, noise_columns:] = lanes.reshape(k1 - k0, 3 * width)
    return rows


def lane_flight_rows(
    streamed: dict[str, slice],
    lane_streamed: dict[str, slice],
    size: int,
    sensors: Sequence[SensorModel | None],
    disturbance: Disturbance | Sequence[Disturbance] | None,
    reference: ReferenceStream | Sequence[ReferenceStream] | None,
    rate: float,
    width: int,
    k0: int,
    k1: int,
    runs: np.ndarray,
) -> np.ndarray:
    """The stream rows of a slice for the W ``runs`` of a batch whose ``noise`` is per lane (each run its own
    sensor's [`noise_rows`][mrpctl.flight.SensorModel.noise_rows], zeros for a noiseless one: the rows that run
    gets alone), placed by the engine's layout (``streamed``, ``lane_streamed``: `LaneEngine`'s offsets of each
    input in a row, a per-lane one's nonzero j of lane l at its offset + j W + l). The torque and the reference
    are shared (one object: streamed) or per run (a sequence: per lane), as the engine takes them."""
    count = k1 - k0
    rows = np.zeros((count, size))
    made: dict[int, tuple[np.ndarray, ...]] = {}  # by run: the padding lanes repeat the batch's first run

    def lanes(name: str, nnz: int, values: Callable[[int], np.ndarray]) -> None:
        block = np.zeros((count, nnz, width))
        for lane, run in enumerate(runs.tolist()):
            block[:, :, lane] = values(run)
        rows[:, lane_streamed[name]] = block.reshape(count, nnz * width)

    def noise(run: int) -> np.ndarray:
        sensor = sensors[run]
        if sensor is None or (sensor.attitude_noise == 0.0 and sensor.rate_noise == 0.0):
            return np.zeros((count, NOISE_SIZE))
        return sensor.noise_rows(k0, k1)  # drawn by noise.c, as for the run alone

    lanes("noise", NOISE_SIZE, noise)
    if "torque" in streamed and isinstance(disturbance, Disturbance):
        rows[:, streamed["torque"]] = disturbance.samples(k0, k1, rate)
    elif "torque" in lane_streamed and isinstance(disturbance, Sequence):
        torques = disturbance
        lanes("torque", 3, lambda run: torques[run].samples(k0, k1, rate))
    if "reference" in streamed and isinstance(reference, ReferenceStream):
        now, error = reference.rows(k0, k1)
        rows[:, streamed["reference"]], rows[:, streamed["reference_error"]] = now, error
    elif "reference" in lane_streamed and isinstance(reference, Sequence):
        references = reference

        def both(run: int) -> tuple[np.ndarray, ...]:
            if run not in made:
                made[run] = tuple(references[run].rows(k0, k1))
            return made[run]

        lanes("reference", REFERENCE_WIDTH, lambda run: both(run)[0])
        lanes("reference_error", REFERENCE_WIDTH, lambda run: both(run)[1])
    return rows


def lane_newest_arrived(
    delays: Sequence[DelayModel | None],
    rate: float,
    depth: int,
    k0: int,
    k1: int,
    newest_before: np.ndarray,
    runs: np.ndarray,
) -> np.ndarray:
    """The (k1 − k0, W) newest-arrived schedules j*(k) of a slice for the W ``runs`` of a batch, each run's own
    ([`newest_arrived_slice`][mrpctl.flight.newest_arrived_slice] of its delay model; a None model is the constant
    delay ``depth``: j*(k) = k − depth); ``newest_before`` (W,) is each lane's j*(k0 − 1)."""
    out = np.empty((k1 - k0, len(runs)), dtype=np.int64)
    made: dict[int, np.ndarray] = {}
    for lane, run in enumerate(runs.tolist()):
        if run not in made:
            model = delays[run]
            made[run] = (
                np.arange(k0 - depth, k1 - depth, dtype=np.int64)
                if model is None
                else newest_arrived_slice(model, rate, depth, k0, k1, int(newest_before[lane]))
            )
        out[:, lane] = made[run]
    return out
