"""The stream rows of the lane engine, one slice at a time: the sensor noise (drawn by ``noise.c``), the
torque of each sample and, for a tracking sample, the reference rows, shared by the lanes of a batch or each
lane's own (a nonzero j of lane l at its offset + j W + l), in the layout ``LaneEngine`` streams them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mrpctl.engines.scalar import noise_rows
from mrpctl.flight import (
    STREAM_ATTITUDE,
    STREAM_JITTER,
    STREAM_RATE,
    DelayKind,
    DelayModel,
    Disturbance,
    SensorModel,
    newest_arrived_slice,
    stream_key,
)
from mrpctl.flight.tracking import REFERENCE_WIDTH, ReferenceStream

__all__ = [
    "OwnStreams",
    "lane_newest_arrived",
    "lane_reference_rows",
    "lane_torque_rows",
    "noise_and_torque_rows",
    "own_streams",
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


@dataclass(frozen=True)
class OwnStreams:
    """Each run's own streams, drawn and scheduled by the lane driver (``mrpctl_lanes_run_own``) as the scalar driver
    does for one run: the noise keys (N, 2) (attitude, rate; uint64) and scales (N, 2) of each run's sensor (None: no
    noise input), and each run's jitter key bits and d_min (N,) (None: no seeded jitter)."""

    noise_keys: np.ndarray | None
    sigmas: np.ndarray | None
    jitter_keys: np.ndarray | None
    d_min: np.ndarray | None

    def batch(self, lanes: np.ndarray, d: int) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """The driver's arrays for the W ``lanes`` (run indices) of a batch: the 2 W keys and scales (lane l's
        attitude one at l, its rate one at W + l) and the (3 + d + 1) W jitter state (keys, d_min, j*(−1) = −1 − d,
        then the arrival ring, which the driver fills)."""
        keys = sigmas = jitter = None
        if self.noise_keys is not None and self.sigmas is not None:
            keys = np.ascontiguousarray(self.noise_keys[lanes].T)
            sigmas = np.ascontiguousarray(self.sigmas[lanes].T)
        if self.jitter_keys is not None and self.d_min is not None:
            width = len(lanes)
            jitter = np.empty((4 + d) * width, dtype=np.int64)
            jitter[:width], jitter[width : 2 * width] = self.jitter_keys[lanes], self.d_min[lanes]
            jitter[2 * width : 3 * width] = -1 - d
        return keys, sigmas, jitter


def own_streams(
    sensors: Sequence[SensorModel | None], delays: Sequence[DelayModel | None], rate: float, d: int, *, noise: bool
) -> OwnStreams:
    """The `OwnStreams` of N runs: with ``noise`` (an engine with a noise input) each run's sensor's keys and 1σ
    (zeros for None: exact zero rows, as ``noise_rows`` gives a noiseless sensor); each run's seeded jitter when every
    delay model is a jitter or None (the constant delay d: d_min = d), else none (a given sequence is scheduled by
    `lane_newest_arrived`)."""
    runs = len(sensors)
    keys = sigmas = jitter_keys = d_min = None
    if noise:
        keys, sigmas = np.zeros((runs, 2), dtype=np.uint64), np.zeros((runs, 2))
        made: dict[int, tuple[list[int], list[float]]] = {}
        for i, sensor in enumerate(sensors):
            if sensor is None or not (sensor.attitude_noise > 0.0 or sensor.rate_noise > 0.0):
                continue
            if id(sensor) not in made:
                pair = [stream_key(sensor.seed, STREAM_ATTITUDE), stream_key(sensor.seed, STREAM_RATE)]
                made[id(sensor)] = pair, [sensor.attitude_noise, sensor.rate_noise]
            keys[i], sigmas[i] = made[id(sensor)]
    seeded = [model is None or model.kind is DelayKind.JITTER for model in delays]
    if all(seeded) and any(model is not None for model in delays):
        jitter_keys, d_min = np.zeros(runs, dtype=np.int64), np.full(runs, d, dtype=np.int64)
        for i, model in enumerate(delays):
            if model is not None:
                jitter_keys[i] = np.uint64(stream_key(model.seed, STREAM_JITTER)).view(np.int64)
                d_min[i] = model.bounds(rate)[0]
    return OwnStreams(keys, sigmas, jitter_keys, d_min)


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
