"""The paper reproduction: every figure and the claims table written, with numbers."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

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
    assert sum(v is Verdict.EXTENDS for v in verdicts.values()) == 1
