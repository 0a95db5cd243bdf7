"""The C source of the scalar engine's driver (``scalar_driver.c`` bound to one sample by #defines) and the
settling tail of a sample whose statistics lag by d samples: the parts of `mrpctl.engines.scalar` that generate code.
"""

from __future__ import annotations

from importlib import resources
from typing import Any

import casadi as ca

from mrpctl.engines.stats import S_DIVERGED, S_MAX_SIGMA, S_SETTLE_OMEGA, S_SETTLE_SIGMA, S_UNSETTLED, STATS_SIZE
from mrpctl.flight.tracking import REFERENCE_BOUND, settling_error_expr
from mrpctl.model import STATE_SIZE

__all__ = ["driver_source", "settling_tail_function"]


def settling_tail_function(name: str) -> ca.Function:
    """``tail(stats, x_meas, reference, j) -> stats_next``: the settling statistic and max |σ|² of sample j from
    its x_meas and its row (t_j), as `engine_sample` folds them for a counted sample: the last samples of a run
    whose sample folds those of k − d (``lagged_settling``), from the ring at the end of the run."""
    stats = ca.SX.sym("stats", STATS_SIZE)
    x_meas = ca.SX.sym("x_meas", STATE_SIZE)
    reference = ca.SX.sym("reference", 9)
    j = ca.SX.sym("j")
    sigma_squared, omega = settling_error_expr(x_meas[0:3], x_meas[3:6], reference[0:3], reference[3:6])
    unsettled = ca.logic_or(sigma_squared >= stats[S_SETTLE_SIGMA], ca.dot(omega, omega) >= stats[S_SETTLE_OMEGA])
    entries = [stats[i] for i in range(STATS_SIZE)]
    entries[S_UNSETTLED] = ca.if_else(unsettled, j, stats[S_UNSETTLED])
    entries[S_MAX_SIGMA] = ca.fmax(stats[S_MAX_SIGMA], sigma_squared)
    return ca.Function(name, [stats, x_meas, reference, j], [ca.vertcat(*entries)])


def driver_source(
    sample: ca.Function,
    rotation: ca.Function | None = None,
    true_error: ca.Function | None = None,
    tail: ca.Function | None = None,
) -> str:
    """``scalar_driver.c`` with the #defines that bind it to ``sample`` (and to ``rotation``, the attitude noise's
    θ -> σ(θ) for a sample of `MRP`; to ``true_error``, the true σ_B/R that closes a kept tracking record, for a
    tracking sample of ``settling_output``)."""
    memory_size = sample.size1_in(1)
    record_width = sample.size1_out("record") if "record" in sample.name_out() else 1
    defines: dict[str, Any] = {
        "MRPCTL_SAMPLE": sample.name(),
        "MRPCTL_RUN": sample.name() + "_run",
        "MRPCTL_SZ_ARG": max(sample.sz_arg(), 8),
        "MRPCTL_SZ_RES": max(sample.sz_res(), 6),
        "MRPCTL_SZ_IW": max(sample.sz_iw(), 1),
        "MRPCTL_SZ_W": max(sample.sz_w(), 1),
        "MRPCTL_STATE": STATE_SIZE + memory_size + STATS_SIZE,
        "MRPCTL_X": STATE_SIZE,
        "MRPCTL_X_MEMORY": STATE_SIZE + memory_size,
        "MRPCTL_S_DIVERGED": S_DIVERGED,
        "MRPCTL_INERTIA_INPUT": int("J" in sample.name_in()),
        "MRPCTL_FLIGHT_INPUT": int("flight" in sample.name_in()),
        "MRPCTL_SENSOR": int("noise" in sample.name_in()),
        "MRPCTL_RING_OUTPUT": int("measurement" in sample.name_out() or "ring" in sample.name_out()),
        "MRPCTL_RECORD_OUTPUT": sample.name_out().index("record") if "record" in sample.name_out() else 0,
        "MRPCTL_TORQUE_INPUT": sample.name_in().index("torque") if "torque" in sample.name_in() else 0,
        "MRPCTL_REFERENCE_INPUT": sample.name_in().index("reference") if "reference" in sample.name_in() else 0,
        "MRPCTL_REFERENCE_BOUND": repr(REFERENCE_BOUND),
        # the lagged statistics' d, fed by the driver from its own d (an input, not a constant of the code)
        "MRPCTL_DELAY_INPUT": sample.name_in().index("delay") if "delay" in sample.name_in() else 0,
        "MRPCTL_RECORD_WIDTH": record_width + (0 if true_error is None else true_error.size1_out(0)),
        "MRPCTL_RING_WIDTH": sample.size1_in(3),
        "MRPCTL_ROTATION_INPUT": int(rotation is not None),
        "MRPCTL_TRUE_ERROR_INPUT": int(true_error is not None),
        "MRPCTL_LAGGED_SETTLING": int(tail is not None),
        # the sample's outputs begin with stats_next (engine_sample's stats_first)
        "MRPCTL_STATS_FIRST": int(sample.name_out(0) == "stats_next"),
    }
    if tail is not None:
        defines["MRPCTL_TAIL"] = tail.name()
        defines["MRPCTL_TAIL_RUN"] = tail.name() + "_run"
        defines["MRPCTL_TAIL_SZ_IW"] = max(tail.sz_iw(), 1)
        defines["MRPCTL_TAIL_SZ_W"] = max(tail.sz_w(), 1)
        defines["MRPCTL_STATS_SIZE"] = STATS_SIZE
    if true_error is not None:
        defines["MRPCTL_TRUE_ERROR"] = true_error.name()
        defines["MRPCTL_TRUE_ERROR_ONE"] = true_error.name() + "_one"
        defines["MRPCTL_TRUE_ERROR_OFFSET"] = record_width  # the true σ_B/R after the sample's own record
        defines["MRPCTL_TRUE_ERROR_SZ_IW"] = max(true_error.sz_iw(), 1)
        defines["MRPCTL_TRUE_ERROR_SZ_W"] = max(true_error.sz_w(), 1)
    if rotation is not None:
        defines["MRPCTL_ROTATION"] = rotation.name()
        defines["MRPCTL_ROTATION_SZ_IW"] = max(rotation.sz_iw(), 1)
        defines["MRPCTL_ROTATION_SZ_W"] = max(rotation.sz_w(), 1)
    header = "".join(f"#define {key} {value}\n" for key, value in defines.items())
    folder = resources.files("mrpctl.engines")
    noise = folder.joinpath("noise.c").read_text(encoding="utf-8")  # the random streams the driver draws
    body = folder.joinpath("scalar_driver.c").read_text(encoding="utf-8")
    return "\n" + noise + header + body
