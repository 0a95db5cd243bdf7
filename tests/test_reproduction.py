"""The paper reproduction: every figure and the claims table written, with numbers."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from mrpctl import paper
from mrpctl.errors import SpecificationError
from mrpctl.reproduction import OUTPUT_FILES, Reproduction, Verdict, reproduce, write_reproduction

pytestmark = pytest.mark.slow


@pytest.fixture
def reproduction(paper_reproduction):
    """The session's reproduction (tests/conftest.py): computed once, shared with test_cli."""
    return paper_reproduction


def test_every_figure_and_table_is_written(reproduction) -> None:
    out, result = reproduction
    names = {p.name for p in result.files}
    for figure in (
        "fig2_tau0_on_current.png",
        "fig3_on_current.png",
        "fig4_on_delayed.png",
        "fig5_on_delayed_zoom.png",
        "fig6_no_switching.png",
        "fig7_boundary_layer.png",
        "eps_study.png",
        "delay_aware.png",
    ):
        assert figure in names
        assert (out / figure).read_bytes()[:4] == b"\x89PNG"
    assert {"claims.md", "summary.json"} <= names
    assert tuple(p.name for p in result.files) == OUTPUT_FILES
    assert not [p for p in out.parent.iterdir() if ".partial-" in p.name]  # no staging folder left


def test_existing_outputs_are_refused_before_any_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "claims.md").write_text("my own notes\n", encoding="utf-8")

    def no_runs(**_: object) -> None:
        raise AssertionError("reproduce() computed before refusing")

    monkeypatch.setattr("mrpctl.reproduction.run_reproduction", no_runs)
    with pytest.raises(SpecificationError, match=r"already holds claims.md.*overwrite"):
        reproduce(tmp_path)
    assert (tmp_path / "claims.md").read_text(encoding="utf-8") == "my own notes\n"


def test_interrupted_write_keeps_old_files(
    reproduction, blank_figures: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C while writing: the old claims.md and summary.json survive whole, no staging folder stays."""
    _, result = reproduction
    out = tmp_path / "results"
    out.mkdir()
    for name in ("claims.md", "summary.json"):
        (out / name).write_text(f"old {name}\n", encoding="utf-8")
    (out / "notes.txt").write_text("user file\n", encoding="utf-8")

    def interrupted(*_: object) -> str:
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr("mrpctl.reproduction._claims_markdown", interrupted)
        with pytest.raises(KeyboardInterrupt):
            write_reproduction(result, out, overwrite=True)
    assert (out / "claims.md").read_text(encoding="utf-8") == "old claims.md\n"
    assert (out / "summary.json").read_text(encoding="utf-8") == "old summary.json\n"
    assert sorted(os.listdir(tmp_path)) == ["results"]
    written = write_reproduction(result, out, overwrite=True)
    assert isinstance(written, Reproduction) and len(written.files) == len(OUTPUT_FILES)
    assert json.loads((out / "summary.json").read_text(encoding="utf-8"))["runs"]
    assert (out / "notes.txt").read_text(encoding="utf-8") == "user file\n"  # other files untouched


def test_claims_carry_numbers(reproduction) -> None:
    out, result = reproduction
    table = (out / "claims.md").read_text(encoding="utf-8")
    rows = [line for line in table.splitlines() if line.startswith("| ") and "verdict" not in line]
    claim_rows = rows[: len(result.claims)]
    assert len(claim_rows) == len(result.claims) >= 10
    for row in claim_rows:
        cells = re.split(r"(?<!\\)\|", row)  # cells between unescaped pipes
        assert len(cells) == 6, row
        measurement = cells[3]
        assert any(ch.isdigit() for ch in measurement), row


def test_summary_agrees_with_runs(reproduction) -> None:
    out, result = reproduction
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    for name, run in result.results.items():
        assert summary["runs"][name]["switch_count"] == run.switch_count
        assert summary["runs"][name]["converged"] == run.converged
    assert summary["design"]["exact_delay_margin"] == pytest.approx(1.5555, abs=1e-3)


def test_headline_findings(reproduction) -> None:
    """The scenario outcomes the paper reports, measured independently of the claims logic."""
    _, result = reproduction
    runs = result.results
    # tau = 0: one switch near the paper's 0.449 s, then convergence.
    fig2 = runs["paper_fig2_tau0_on_current"]
    assert fig2.switch_count == 1 and abs(fig2.first_switch_time - paper.PAPER_FIRST_SWITCH_TIME) < 0.02
    assert fig2.converged
    # tau = 0.5, switching on the delayed measurement: chatters to the end.
    fig4 = runs["paper_fig4_on_delayed"]
    assert fig4.last_switch_time > fig4.t_final - 1.0 and not fig4.converged
    # tau = 0.5 without switching: converges, |sigma| slightly above 1.
    fig6 = runs["paper_fig6_no_switching"]
    assert fig6.converged and 1.0 < fig6.max_sigma < 1.1
    # mrpctl's delay-aware rule: at most two switches and convergence.
    aware = runs["delay_aware"]
    assert aware.switch_count <= 2 and aware.converged
    verdicts = {c.claim: c.verdict for c in result.claims}
    # mrpctl's own rows: the delay-aware rule, 3 of the flight loop, one distribution per rule
    # ... and the predictor study: 8 runs and the two exact inertia margins
    assert sum(v is Verdict.EXTENDS for v in verdicts.values()) == 1 + 3 + 4 + 8 + 2
    study = result.predictor
    by = {(row.controller.split(",")[0], row.e): row for row in study.rows}
    fast, slow = by[("predictor", 0.0)], by[("certified PD", 0.0)]
    assert fast.settling_time is not None and slow.settling_time is not None
    assert fast.settling_time < slow.settling_time / 5  # prediction removes the delay's limit on the gains
    # 5 % and 10 % inertia errors are inside the exact (linearised) margin, and those runs settle
    assert study.predictor_margin.lower < 0.0 < 0.10 < study.predictor_margin.upper
    assert by[("predictor", 0.05)].settling_time is not None and by[("predictor", 0.10)].settling_time is not None
    assert fig4.switch_count == 30198  # the reproduced Fig. 4 number (README) is unchanged by the flight rows


def test_flight_rows_agree_with_the_paper_rules(reproduction) -> None:
    """The controller-side rule's noise-free rows equal the paper rules they reduce to (design/flight.md)."""
    _, result = reproduction
    runs, rows = result.results, result.studies["noise_delta"]
    on_current, no_switching = runs["paper_fig3_on_current"], runs["paper_fig6_no_switching"]
    plain = runs["flight_hysteretic_alpha_1"]
    # delta = 0 is OnCurrent bit for bit; its logic switch is the plant's one delay later
    assert plain.settling_time == on_current.settling_time and np.array_equal(plain.sigma, on_current.sigma)
    assert plain.switch_indices.tolist() == [on_current.switch_indices[0] + plain.delay_samples]
    # alpha > max |sigma| of the unswitched run (1.016) never switches: NoSwitching's run
    assert no_switching.max_sigma < 1.05
    for row in rows:
        if row["attitude_noise"] == 0.0 and row["alpha"] >= 1.05:
            assert row["switch_count"] == 0 and row["settling_time"] == no_switching.settling_time
        if row["attitude_noise"] == 0.0 and row["alpha"] == 1.0:
            assert row["switch_count"] == 1 and row["settling_time"] == on_current.settling_time
    # noise chatters without hysteresis and not with it; more noise, more changes
    by_key = {(row["attitude_noise"], row["alpha"]): row["switch_count"] for row in rows}
    assert by_key[(0.01, 1.0)] > by_key[(0.001, 1.0)] > by_key[(0.0, 1.0)] == 1
    assert all(count == 0 for (noise, alpha), count in by_key.items() if alpha >= 1.05)
    assert len(rows) == 12 and runs["flight-paper"].converged


def test_distribution_rows(reproduction) -> None:
    out, result = reproduction
    rows = result.studies["distributions"]
    assert len(rows) == 4 * 3 and all(row["runs"] == 30 for row in rows)
    by_rule = {}
    for row in rows:
        by_rule.setdefault(row["rule"], []).append(row)
    assert all(row["converged"] == 0 and row["switching_in_last_10s"] == 30 for row in by_rule["on-delayed"])
    assert all(row["converged"] == 30 for row in by_rule["hysteretic alpha = 1.2"])
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert (
        summary["flight"]["distributions"] == rows and summary["flight"]["noise_delta"] == result.studies["noise_delta"]
    )
    table = (out / "claims.md").read_text(encoding="utf-8")
    assert "## Noise x delta" in table and "## Switching claims as distributions" in table
    for name in ("noise_delta_study.png", "distributions.png", "flight_paper.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG"


def test_perturbed_states_are_small_seeded_rotations_of_the_paper_state() -> None:
    from scipy.spatial.transform import Rotation

    from mrpctl import mrp
    from mrpctl.reproduction import perturbed_states

    states = perturbed_states(200, seed=5)
    assert np.array_equal(states, perturbed_states(200, seed=5))
    assert not np.array_equal(states, perturbed_states(200, seed=6))
    rotations = Rotation.from_quat(mrp.to_quaternion(states[:, :3])[:, [1, 2, 3, 0]])
    paper_rotation = Rotation.from_quat(mrp.to_quaternion(paper.INITIAL_STATE[:3])[[1, 2, 3, 0]])
    angles = (rotations * paper_rotation.inv()).magnitude()
    assert np.max(angles) <= np.sqrt(3) * np.radians(0.5) * (1 + 1e-12) and np.min(angles) > 0
    delta_omega = 4.0 * states[:, 3:] - 4.0 * paper.INITIAL_STATE[3:]
    assert np.max(np.abs(delta_omega)) <= 0.02 and np.max(np.abs(delta_omega)) > 0.015
    assert np.all(np.linalg.norm(states[:, :3], axis=1) < 1.0)
