"""Campaign summaries (convergence with confidence intervals, distributions, worst cases), figures and replay.

Figures are built as `matplotlib.figure.Figure` objects (no backend is selected and
no pyplot state is touched) and written atomically.
"""

from __future__ import annotations

import json
import math
import os
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr
from scipy.stats import binomtest

from mrpctl._validation import integer
from mrpctl.campaign._task import run_models, run_tracking, simulate_chunk, tracking_keywords
from mrpctl.campaign.integrity import StoreDamagedError
from mrpctl.campaign.sampling import run_inputs
from mrpctl.campaign.simulation import METRICS, POINTING_METRICS, flight_keywords
from mrpctl.campaign.store import STORE_NAME, open_campaign, spec_of, stored_names, stored_noise_revision
from mrpctl.campaign.wheels import WHEEL_METRICS, wheel_summary, wheel_summary_lines
from mrpctl.errors import SpecificationError
from mrpctl.flight import NOISE_REVISION
from mrpctl.flight.tracking import DEFAULT_POINTING_TOLERANCE
from mrpctl.simulation import simulate
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import rest_momentum_load

if TYPE_CHECKING:
    # deferred: matplotlib, only when a figure is made
    from matplotlib.figure import Figure

    from mrpctl.simulation import SimulationResult

__all__ = [
    "WORST_CRITERION",
    "CampaignReport",
    "ReplayResult",
    "RuleSummary",
    "WorstCase",
    "clopper_pearson_interval",
    "figures",
    "replay",
    "report",
    "wilson_interval",
    "write_report",
]


def _proportion_ci(successes: int, trials: int, confidence: float, method: str) -> tuple[float, float]:
    if trials == 0:
        return 0.0, 1.0
    ci = binomtest(int(successes), int(trials)).proportion_ci(confidence_level=confidence, method=method)
    return float(ci.low), float(ci.high)


def wilson_interval(successes: int, trials: int, *, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (Wilson 1927), from ``scipy.stats.binomtest``.

    Returns (0, 1) when there are no trials.
    """
    return _proportion_ci(successes, trials, confidence, "wilson")


def clopper_pearson_interval(successes: int, trials: int, *, confidence: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper–Pearson 1934) interval of a binomial proportion, from ``scipy.stats.binomtest``.

    Returns (0, 1) when there are no trials.
    """
    return _proportion_ci(successes, trials, confidence, "exact")


@dataclass(frozen=True)
class RuleSummary:
    """The outcome of the runs of one rule (the rules are crossed with the same cases).

    Attributes
    ----------
    rule : str
        The rule's campaign-file string.
    runs, converged, diverged : int
        Runs of this rule stored so far; of them, settled; diverged.
    convergence_rate : float
        converged / runs (NaN without runs).
    wilson : tuple of float
        95 % Wilson interval of the rate.
    settling_quantiles, switch_quantiles : dict
        Median, p95 and max settling time of the converged runs (s) and of the switch count.
    """

    rule: str
    runs: int
    converged: int
    diverged: int
    convergence_rate: float
    wilson: tuple[float, float]
    settling_quantiles: dict[str, float]
    switch_quantiles: dict[str, float]


@dataclass(frozen=True)
class WorstCase:
    """One of the worst runs, with the command that replays it."""

    run: int
    reason: str
    settling_time: float
    switch_count: int
    max_sigma: float
    initial_angle: float
    initial_rate: float
    command: str
    rule: str = ""
    #: A tracking campaign's pointing max after settling (deg) and slew time (s) of the run (NaN: none, or regulation).
    pointing_max: float = math.nan
    slew_time: float = math.nan


#: How the worst runs are ordered (most severe first), as the report states it.
WORST_CRITERION = (
    "most severe first: diverged, then not settled by the end of the run (more switches first), "
    "then settled, slowest to settle first"
)


@dataclass(frozen=True, eq=False)
class CampaignReport:
    """Summary of a campaign's complete runs.

    Attributes
    ----------
    name : str
        Campaign name.
    count, complete : int
        Runs in the campaign; runs stored so far.
    converged, diverged : int
        Runs that settled; runs that diverged.
    convergence_rate : float
        converged / complete.
    wilson, clopper_pearson : tuple of float
        95 % confidence intervals of the convergence rate.
    settling_quantiles : dict
        Median, 95th percentile and maximum settling time of the converged runs (s).
    switch_quantiles : dict
        Median, 95th percentile and maximum switch count.
    peak_torque_max : float
        Largest peak torque (N m), NaN when not computed.
    worst : tuple of WorstCase
        The worst runs in the order of `WORST_CRITERION`.
    """

    name: str
    count: int
    complete: int
    converged: int
    diverged: int
    convergence_rate: float
    wilson: tuple[float, float]
    clopper_pearson: tuple[float, float]
    settling_quantiles: dict[str, float]
    switch_quantiles: dict[str, float]
    peak_torque_max: float
    worst: tuple[WorstCase, ...] = field(repr=False)
    by_rule: tuple[RuleSummary, ...] = field(default=(), repr=False)
    #: A tracking campaign's pointing (None when the campaign regulates): the quantiles (median, p95, max) of
    #: ``pointing_max_deg`` and ``pointing_rms_deg`` (Φ_B/R after the settling time, deg, over the settled runs)
    #: and ``slew_time_s`` (over the runs that came within the tolerance), with ``slewed`` (how many did).
    pointing: dict[str, Any] | None = field(default=None, repr=False)
    #: The store's check: ``verified`` (False: written without checksum records) and the ``damaged`` chunks
    #: left out of this report (only with ``intact_only``).
    integrity: dict[str, Any] = field(default_factory=dict, repr=False)
    #: A campaign on wheels: the wheel metrics per wheel ([wheel_summary][mrpctl.campaign.wheels.wheel_summary]).
    wheels: dict[str, Any] | None = field(default=None, repr=False)

    def summary(self) -> dict[str, Any]:
        """The report as JSON-ready values."""
        return {
            "name": self.name,
            "count": self.count,
            "complete": self.complete,
            "converged": self.converged,
            "diverged": self.diverged,
            "convergence_rate": self.convergence_rate,
            "wilson_95": list(self.wilson),
            "clopper_pearson_95": list(self.clopper_pearson),
            "settling_time_s": self.settling_quantiles,
            "switch_count": self.switch_quantiles,
            "peak_torque_max_Nm": None if math.isnan(self.peak_torque_max) else self.peak_torque_max,
            "worst_criterion": WORST_CRITERION,
            "worst": [self._worst_entry(case) for case in self.worst],
            "by_rule": [{**entry.__dict__, "wilson": list(entry.wilson)} for entry in self.by_rule],
            "integrity": self.integrity,
            **({} if self.pointing is None else {"pointing": self.pointing}),
            **({} if self.wheels is None else {"wheels": self.wheels}),
        }

    def _worst_entry(self, case: WorstCase) -> dict[str, Any]:
        entry = dict(case.__dict__)
        if self.pointing is None:  # a regulation campaign's summary is as before
            entry.pop("pointing_max")
            entry.pop("slew_time")
        return entry

    def __str__(self) -> str:
        s, w = self.settling_quantiles, self.switch_quantiles
        lines = [
            f"campaign {self.name}: {self.complete}/{self.count} runs complete",
            f"  converged     {self.converged}/{self.complete} = {self.convergence_rate:.4%}  "
            f"(95 % Wilson [{self.wilson[0]:.4%}, {self.wilson[1]:.4%}], "
            f"Clopper-Pearson [{self.clopper_pearson[0]:.4%}, {self.clopper_pearson[1]:.4%}])",
            f"  diverged      {self.diverged}",
            f"  settling (s)  median {s['median']:.4g}, p95 {s['p95']:.4g}, max {s['max']:.4g} (converged runs)",
            f"  switches      median {w['median']:.4g}, p95 {w['p95']:.4g}, max {w['max']:.4g}",
            f"  peak torque   max {self.peak_torque_max:.4g} N m",
            *wheel_summary_lines(self.wheels),
        ]
        if self.pointing is not None:
            p = self.pointing
            for key, label in (
                ("pointing_max_deg", "pointing max after settling (deg)"),
                ("pointing_rms_deg", "pointing RMS after settling (deg)"),
                ("slew_time_s", "slew time (s)"),
            ):
                q = p[key]
                lines.append(f"  {label:<34} median {q['median']:.4g}, p95 {q['p95']:.4g}, max {q['max']:.4g}")
            lines.append(
                f"  slewed        {p['slewed']}/{self.complete} runs came within {p['tolerance_deg']:g} deg of the "
                "reference to the end (slew time); pointing over the settled runs"
            )
        if self.integrity and not self.integrity.get("verified", True):
            lines.append(f"  integrity     NOT VERIFIED: {self.integrity.get('note', 'no checksum records')}")
        damaged = self.integrity.get("damaged", []) if self.integrity else []
        if damaged:
            lines.append(
                f"  integrity     {len(damaged)} damaged chunk(s) LEFT OUT (runs "
                + ", ".join(f"{d['runs'][0]}-{d['runs'][1]}" for d in damaged)
                + "); repair with mrpctl campaign run CAMPAIGN.toml --out OUT"
            )
            for d in damaged:
                lines.append(
                    f"    chunk {d['chunk']} (runs {d['runs'][0]}-{d['runs'][1]}), {d['array']}: {d['problem']}"
                )
        if len(self.by_rule) > 1:
            lines.append("  by rule (the same cases under each rule):")
            lines.append(
                f"    {'rule':<24} {'runs':>7} {'converged':>10} {'fraction':>8} {'95 % Wilson':>20} {'diverged':>8} "
                f"{'settle_med_s':>12} {'settle_p95_s':>12} {'switch_med':>10} {'switch_max':>10}"
            )
            for r in self.by_rule:
                lines.append(
                    f"    {r.rule:<24} {r.runs:>7} {r.converged:>10} {r.convergence_rate:>8.2%} "
                    f"{f'[{r.wilson[0]:.2%}, {r.wilson[1]:.2%}]':>20} {r.diverged:>8} "
                    f"{r.settling_quantiles['median']:>12.4g} {r.settling_quantiles['p95']:>12.4g} "
                    f"{r.switch_quantiles['median']:>10.4g} {r.switch_quantiles['max']:>10.4g}"
                )
        tracking = self.pointing is not None
        lines += [
            f"  worst cases ({WORST_CRITERION}):",
            f"    {'run':>8} {'rule':<20} {'reason':<12} {'settling_s':>10} {'switches':>8} {'max|sigma|':>10} "
            f"{'angle_deg':>9} {'rate_rad/s':>10}"
            + (f" {'point_max_deg':>13} {'slew_time_s':>11}" if tracking else "")
            + "  replay",
        ]
        for c in self.worst:
            lines.append(
                f"    {c.run:>8} {c.rule:<20} {c.reason:<12} {c.settling_time:>10.4g} {c.switch_count:>8} "
                f"{c.max_sigma:>10.4g} {math.degrees(c.initial_angle):>9.2f} {c.initial_rate:>10.4g}"
                + (f" {c.pointing_max:>13.4g} {c.slew_time:>11.4g}" if tracking else "")
                + f"  {c.command}"
            )
        return "\n".join(lines)


def _quantiles(values: np.ndarray) -> dict[str, float]:
    if values.size == 0:
        return {"median": math.nan, "p95": math.nan, "max": math.nan}
    return {
        "median": float(np.median(values)),
        "p95": float(np.quantile(values, 0.95)),
        "max": float(np.max(values)),
    }


def _dataset(source: str | Path | xr.Dataset, intact_only: bool = False) -> xr.Dataset:
    return source if isinstance(source, xr.Dataset) else open_campaign(source, intact_only=intact_only)


def strict_json(value: Any) -> Any:
    """``value`` with every NaN or infinite float replaced by None (JSON ``null``), recursively."""
    if isinstance(value, dict):
        return {str(k): strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def report(
    source: str | Path | xr.Dataset, *, worst: int = 10, out: str | Path | None = None, intact_only: bool = False
) -> CampaignReport:
    """Summarise a campaign's complete runs (a results folder or its dataset).

    ``out`` is the folder written into the replay commands (default: ``source`` when it is a path).
    A folder is checked first ([open_campaign][mrpctl.campaign.store.open_campaign]): a damaged chunk raises
    ``StoreDamagedError`` naming it, unless ``intact_only``, which reports over the intact runs and lists
    the damaged chunks in ``integrity`` (and in the table).
    """
    dataset = _dataset(source, intact_only)
    worst = integer("worst", worst, minimum=0)
    folder = str(out if out is not None else (source if not isinstance(source, xr.Dataset) else "OUT"))
    n = dataset.sizes["run"]
    converged = np.asarray(dataset["converged"], dtype=bool)
    diverged = np.asarray(dataset["diverged"], dtype=bool)
    settling = np.asarray(dataset["settling_time"], dtype=float)
    switches = np.asarray(dataset["switch_count"], dtype=np.int64)
    k = int(converged.sum())
    # worst first: diverged, then not settled (more switches first), then the slowest to settle
    severity = np.where(diverged, 0, np.where(~converged, 1, 2))
    order = np.lexsort((-switches, -np.nan_to_num(settling, nan=np.inf), severity))[:worst]
    runs = np.asarray(dataset["run"])
    labels = _rule_labels(dataset)
    rule_index = np.asarray(dataset["rule"], dtype=np.int64) if "rule" in dataset else np.zeros(n, dtype=np.int64)
    cases = []
    for i in order:
        reason = "diverged" if diverged[i] else ("not settled" if not converged[i] else "slow")
        cases.append(
            WorstCase(
                run=int(runs[i]),
                reason=reason,
                settling_time=float(settling[i]),
                switch_count=int(switches[i]),
                max_sigma=float(dataset["max_sigma"][i]),
                initial_angle=float(dataset["initial_angle"][i]),
                initial_rate=float(dataset["initial_rate"][i]),
                command=f"mrpctl campaign replay {shlex.quote(folder)} --run {int(runs[i])}",
                rule=labels[int(rule_index[i])] if 0 <= int(rule_index[i]) < len(labels) else "?",
                **(
                    {"pointing_max": float(dataset["pointing_max"][i]), "slew_time": float(dataset["slew_time"][i])}
                    if "pointing_max" in dataset
                    else {}
                ),
            )
        )
    by_rule = []
    for r, label in enumerate(labels):
        mine = rule_index == r
        runs_r, k_r = int(mine.sum()), int((converged & mine).sum())
        by_rule.append(
            RuleSummary(
                rule=label,
                runs=runs_r,
                converged=k_r,
                diverged=int((diverged & mine).sum()),
                convergence_rate=k_r / runs_r if runs_r else math.nan,
                wilson=wilson_interval(k_r, runs_r),
                settling_quantiles=_quantiles(settling[converged & mine]),
                switch_quantiles=_quantiles(switches[mine].astype(float)),
            )
        )
    peak = np.asarray(dataset["peak_torque"], dtype=float)
    pointing = None
    if "pointing_max" in dataset:
        slew = np.asarray(dataset["slew_time"], dtype=float)
        pointing = {
            "pointing_max_deg": _quantiles(_finite(dataset["pointing_max"])),
            "pointing_rms_deg": _quantiles(_finite(dataset["pointing_rms"])),
            "slew_time_s": _quantiles(slew[np.isfinite(slew)]),
            "slewed": int(np.isfinite(slew).sum()),
            "tolerance_deg": _pointing_tolerance(dataset),
        }
    return CampaignReport(
        name=str(dataset.attrs.get("name", "campaign")),
        count=int(dataset.attrs.get("count", n)),
        complete=n,
        converged=k,
        diverged=int(diverged.sum()),
        convergence_rate=k / n if n else math.nan,
        wilson=wilson_interval(k, n),
        clopper_pearson=clopper_pearson_interval(k, n),
        settling_quantiles=_quantiles(settling[converged]),
        switch_quantiles=_quantiles(switches.astype(float)),
        peak_torque_max=float(np.nanmax(peak)) if np.any(np.isfinite(peak)) else math.nan,
        worst=tuple(cases),
        by_rule=tuple(by_rule),
        integrity=json.loads(str(dataset.attrs.get("integrity", "{}"))),
        pointing=pointing,
        wheels=_wheels(dataset),
    )


def _finite(values: Any) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    return array[np.isfinite(array)]


def _pointing_tolerance(dataset: xr.Dataset) -> float:
    """The slew time's tolerance (deg) of a tracking campaign: the campaign's ``[reference]
    pointing_tolerance_deg`` where given, else simulate's default."""
    table = json.loads(str(dataset.attrs.get("campaign", "{}"))).get("reference", {})
    value = table.get("pointing_tolerance_deg", DEFAULT_POINTING_TOLERANCE) if isinstance(table, dict) else None
    return float(value) if isinstance(value, int | float) else DEFAULT_POINTING_TOLERANCE


def _wheels(dataset: xr.Dataset) -> dict[str, Any] | None:
    """The wheel summary of a campaign on wheels (its cluster's limits from the stored campaign), or None."""
    if "wheel_peak_speed" not in dataset:
        return None
    base = spec_of(dataset).base
    cluster = base.wheels
    limits = None if cluster is None else (np.asarray(cluster.speed_limit), np.asarray(cluster.momentum_capacity))
    loads = None
    external = base.reference is not None or base.gravity_gradient or "flight_disturbance_rows" in dataset
    if "disturbance" in dataset:
        external = external or bool(np.any(np.asarray(dataset["disturbance"], dtype=float) != 0.0))
    if cluster is not None and not external:  # the total momentum is conserved and the target is the origin
        sigma0, omega0 = np.asarray(dataset["sigma0"], dtype=float), np.asarray(dataset["omega0"], dtype=float)
        inertia = np.asarray(dataset["inertia"], dtype=float)
        known = np.all(np.isfinite(sigma0), axis=1) & np.all(np.isfinite(omega0), axis=1)
        known &= np.all(np.isfinite(inertia), axis=(1, 2))
        loads = np.full(len(sigma0), np.nan)
        if np.any(known):
            loads[known] = rest_momentum_load(cluster, inertia[known], sigma0[known], omega0[known])
    return wheel_summary(dataset, *(limits or (None, None)), loads=loads)


def _rule_labels(dataset: xr.Dataset) -> list[str]:
    """The rules crossed with the cases (attrs["rules"]), or the one rule of an older store."""
    if "rules" in dataset.attrs:
        return [str(label) for label in json.loads(str(dataset.attrs["rules"]))]
    return [str(dataset.attrs.get("rule", "rule"))]


def figures(source: str | Path | xr.Dataset) -> dict[str, Figure]:
    """The report's figures: settling-time and switch-count histograms, outcome against the initial state; a
    tracking campaign's also its slew times and pointing errors (``pointing``)."""
    # deferred: matplotlib, only when a figure is made
    from matplotlib.figure import Figure

    dataset = _dataset(source)
    converged = np.asarray(dataset["converged"], dtype=bool)
    diverged = np.asarray(dataset["diverged"], dtype=bool)
    settling = np.asarray(dataset["settling_time"], dtype=float)
    switches = np.asarray(dataset["switch_count"], dtype=np.int64)
    n = len(converged)
    out: dict[str, Figure] = {}

    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    if converged.any():
        ax.hist(settling[converged], bins=min(50, max(5, int(np.sqrt(converged.sum())))), color="tab:blue")
    ax.set_xlabel("settling time (s): |σ| < 1e-2 and |ω| < 1e-3 rad/s to the end")
    ax.set_ylabel("runs")
    ax.set_title(
        f"settling time of {int(converged.sum())}/{n} converged runs "
        f"({n - int(converged.sum())} not settled, {int(diverged.sum())} diverged, not shown)",
        fontsize=9,
    )
    out["settling_time"] = fig

    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    positive = switches[switches > 0]
    zero = int(np.sum(switches == 0))
    if positive.size:
        top = max(2.0, float(positive.max()) * 1.05)
        bins = np.unique(np.round(np.geomspace(1.0, top, 40)))
        ax.hist(positive, bins=np.append(bins, bins[-1] + 1).tolist(), color="tab:orange")
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel("shadow-set switches per run (log)")
    ax.set_ylabel("runs (log)")
    ax.set_title(f"switch count of {n} runs ({zero} runs never switched, not on the log axis)", fontsize=9)
    out["switch_count"] = fig

    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    angle = np.degrees(np.asarray(dataset["initial_angle"], dtype=float))
    rate = np.asarray(dataset["initial_rate"], dtype=float)
    failed = ~converged & ~diverged
    ax.scatter(angle[converged], rate[converged], s=4, color="tab:green", label="converged", alpha=0.5)
    ax.scatter(angle[failed], rate[failed], s=12, marker="x", color="tab:orange", label="not settled")
    ax.scatter(angle[diverged], rate[diverged], s=14, marker="x", color="crimson", label="diverged")
    ax.set_xlabel("initial principal angle Φ₀ (deg)")
    ax.set_ylabel("initial rate |ω₀| (rad/s)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title("outcome against the initial state", fontsize=9)
    out["outcome_vs_initial"] = fig
    if "pointing_max" in dataset:
        out["pointing"] = _pointing_figure(dataset)
    return out


def _pointing_figure(dataset: xr.Dataset) -> Figure:
    """A tracking campaign's slew times and pointing errors after settling, one histogram each."""
    # deferred: matplotlib, only when a figure is made
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 3.6), layout="constrained")
    left, right = fig.subplots(1, 2)
    slew = _finite(dataset["slew_time"])
    peak, rms = _finite(dataset["pointing_max"]), _finite(dataset["pointing_rms"])
    n = dataset.sizes["run"]
    if slew.size:
        left.hist(slew, bins=min(50, max(5, int(np.sqrt(slew.size)))), color="tab:blue")
    left.set_xlabel(f"slew time (s): pointing error < {_pointing_tolerance(dataset):g} deg to the end")
    left.set_ylabel("runs")
    left.set_title(f"slew time of {slew.size}/{n} runs ({n - slew.size} never within the tolerance)", fontsize=9)
    if peak.size:
        bins = min(50, max(5, int(np.sqrt(peak.size))))
        right.hist(peak, bins=bins, color="tab:red", alpha=0.6, label="max")
        right.hist(rms, bins=bins, color="tab:green", alpha=0.6, label="RMS")
        right.legend(fontsize=8)
    right.set_xlabel("pointing error after settling (deg)")
    right.set_ylabel("runs")
    right.set_title(f"pointing of {peak.size}/{n} settled runs", fontsize=9)
    return fig


def _save(fig: Figure, path: Path) -> Path:
    """Write a figure atomically (temporary file, then rename)."""
    temporary = path.with_name(path.name + ".tmp")
    fig.savefig(temporary, format=path.suffix.lstrip(".") or "png", dpi=110)
    os.replace(temporary, path)
    return path


def _write_text(path: Path, text: str) -> None:
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(text, encoding="utf-8")
    os.replace(temporary, path)


def write_report(out: str | Path, *, worst: int = 10, intact_only: bool = False) -> tuple[CampaignReport, list[Path]]:
    """Write ``out/report/``: report.md (the table), summary.json (strict JSON: NaN and infinities are
    ``null``) and one PNG per figure. ``intact_only``: as in [report][mrpctl.campaign.report.report]."""
    out = Path(out)
    dataset = open_campaign(out, intact_only=intact_only)
    result = report(dataset, worst=worst, out=out)
    folder = out / "report"
    folder.mkdir(parents=True, exist_ok=True)
    written = [_save(fig, folder / f"{name}.png") for name, fig in figures(dataset).items()]
    markdown = f"# Campaign {result.name}\n\n```\n{result}\n```\n\n" + "".join(
        f"![{p.stem}]({p.name})\n\n" for p in written
    )
    _write_text(folder / "report.md", markdown)
    _write_text(folder / "summary.json", json.dumps(strict_json(result.summary()), indent=2, allow_nan=False) + "\n")
    return result, [folder / "report.md", folder / "summary.json", *written]


@dataclass(frozen=True, eq=False)
class ReplayResult:
    """A run re-simulated on its own from (seed, run index), against what the campaign stored.

    Attributes
    ----------
    run : int
        Run index.
    stored, replayed : dict
        The stored and the recomputed inputs and metrics.
    mismatches : tuple of str
        Names whose values differ (bit for bit; NaN equals NaN).
    trajectory : SimulationResult or None
        The full run, when asked for.
    noise_revisions : tuple of int or None
        (stored, current) `NOISE_REVISION` when they differ and the campaign has attitude
        noise: its runs then differ in their last bits by design; None otherwise.
    damage : str or None
        The run's chunk does not match its checksum record (what is wrong and the repairing command); the
        stored values were still decodable and are compared. None when the chunk is intact.
    """

    run: int
    stored: dict[str, np.ndarray] = field(repr=False)
    replayed: dict[str, np.ndarray] = field(repr=False)
    mismatches: tuple[str, ...]
    trajectory: SimulationResult | None = field(default=None, repr=False)
    noise_revisions: tuple[int, int] | None = None
    damage: str | None = None

    @property
    def matches(self) -> bool:
        """True when every input and metric is reproduced exactly."""
        return not self.mismatches

    def __str__(self) -> str:
        lines = [
            f"replay of run {self.run}: "
            + ("identical to the stored run" if self.matches else "DIFFERS in " + ", ".join(self.mismatches))
        ]
        if self.damage is not None:
            lines.append(f"  the run's chunk is DAMAGED (does not match its checksum record): {self.damage}")
        if self.noise_revisions is not None:
            lines.append(
                f"  the store was written with noise revision {self.noise_revisions[0]}, this mrpctl computes revision "
                f"{self.noise_revisions[1]}: runs with attitude noise differ in their last bits (see CHANGELOG.md)"
            )
        names = [
            *METRICS,
            *(key for key in POINTING_METRICS if key in self.stored),
            *(key for key in WHEEL_METRICS if key in self.stored),
        ]
        width = max(18, *(len(name) for name in names))
        for name in names:
            lines.append(f"  {name:<{width}} stored {self.stored[name]!s:>24}  replayed {self.replayed[name]!s:>24}")
        return "\n".join(lines)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.tobytes() == b.tobytes():
        return True
    return a.dtype.kind == "f" and bool(np.array_equal(a, b, equal_nan=True))


def replay(out: str | Path, run: int, *, trajectory: bool = False) -> ReplayResult:
    """Re-run run ``run`` of the campaign in ``out`` alone and compare it with the stored values.

    Raises
    ------
    SpecificationError
        If the run is out of range or its chunk is not complete yet.
    StoreDamagedError
        If the run's chunk does not match its checksum record (other chunks' damage does not stop a replay).
    """
    dataset = open_campaign(out, intact_only=True)
    count = int(dataset.attrs["count"])
    run = integer("run", run, minimum=0, maximum=count - 1)
    damage_text = None
    for damage in json.loads(str(dataset.attrs.get("integrity", "{}"))).get("damaged", []):
        first, last = damage["runs"]
        if first <= run <= last:
            damage_text = (
                f"chunk {damage['chunk']} (runs {first}-{last}), array {damage['array']}: {damage['file']} "
                f"{damage['problem']}; repair with: mrpctl campaign run CAMPAIGN.toml --out {out}"
            )
            dataset = _damaged_run(out, run, dataset.attrs, damage_text)
    if run not in set(np.asarray(dataset["run"]).tolist()):
        raise SpecificationError(f"run: run {run} has not been stored yet (its chunk is not complete)")
    spec = spec_of(dataset)
    values = simulate_chunk(spec, run, run + 1)
    names = stored_names(spec.tracking) + [name for name in WHEEL_METRICS if name in dataset]
    stored = {name: np.asarray(dataset[name].sel(run=run).values) for name in names}
    replayed = {name: np.asarray(values[name][0]) for name in names}
    mismatches = tuple(name for name in names if not _same(stored[name], replayed[name]))
    result = None
    if trajectory:
        result = _trajectory(spec, run, values)
    revision = stored_noise_revision(dataset.attrs)
    revisions = (revision, NOISE_REVISION) if spec.attitude_noisy and revision != NOISE_REVISION else None
    return ReplayResult(
        run=run,
        stored=stored,
        replayed=replayed,
        mismatches=mismatches,
        trajectory=result,
        noise_revisions=revisions,
        damage=damage_text,
    )


def _damaged_run(out: str | Path, run: int, attrs: dict[str, Any], damage: str) -> xr.Dataset:
    """Run ``run`` read from a chunk that fails its checksum (it may still decode: then it is compared)."""
    try:
        with xr.open_zarr(str(Path(out) / STORE_NAME), consolidated=False) as stored:
            one = stored.drop_vars("chunk_complete").isel(run=[run]).load()
    except Exception as exc:
        raise StoreDamagedError(f"out: run {run} cannot be read from {out}: {damage} ({type(exc).__name__})") from None
    one.attrs = dict(attrs)
    return one


def _trajectory(spec: Any, run: int, values: dict[str, np.ndarray]) -> SimulationResult:

    inputs = run_inputs(spec, run)
    base = spec.base
    rule, models = run_models(spec, inputs, 0)
    return simulate(
        Spacecraft(inputs.inertia[0]),
        inputs.gain_scale[0] * base.K,
        inputs.x0[0],
        tau=float(inputs.tau[0]),
        rule=rule,
        t_final=base.t_final,
        rate=base.rate,
        history=base.history,
        substeps=base.substeps,
        settling_attitude=base.settling_attitude,
        settling_rate=base.settling_rate,
        **({} if models is None else flight_keywords(models)),
        **({} if spec.predictor is None else {"predictor": spec.predictor}),
        **({} if not spec.tracking else {"reference": run_tracking(spec, inputs, 0), **tracking_keywords(spec)}),
        **({} if base.wheels is None else {"wheels": base.wheels}),
        **({} if base.law is None else {"law": base.law}),
    )


def plot_replay(result: ReplayResult) -> Figure:
    """σ, ω and u of a replayed run against t, with the switches marked."""
    # deferred: matplotlib, only when a figure is made
    from matplotlib.figure import Figure

    if result.trajectory is None:
        raise SpecificationError("result: replay(..., trajectory=True) is needed to plot a run")
    run = result.trajectory
    fig = Figure(figsize=(7.0, 6.5), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, values, label in (
        (axes[0], run.sigma, "σ"),
        (axes[1], run.omega, "ω (rad/s)"),
        (axes[2], run.u, "u (N m)"),
    ):
        for i in range(3):
            ax.plot(run.t, values[:, i], lw=0.9, label=f"{label.split()[0]}{i + 1}")
        ax.set_ylabel(label)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        for t in run.switch_times[:200]:
            ax.axvline(t, color="crimson", lw=0.4, alpha=0.5)
    axes[2].set_xlabel("t (s)")
    axes[0].set_title(f"run {result.run}: {run.rule}, τ = {run.tau:g} s, {run.switch_count} switches", fontsize=9)
    return fig


def save_replay_plot(result: ReplayResult, path: str | Path) -> Path:
    """Write [`plot_replay`][mrpctl.campaign.report.plot_replay] to ``path`` atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return _save(plot_replay(result), path)
