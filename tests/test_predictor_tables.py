"""design/predictor.md's tables of the paper case are what bench/predictor_tables.py computes from the code."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from mrpctl.predictor import MarginInterval

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("predictor_tables", ROOT / "bench" / "predictor_tables.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_margin_is_printed_only_where_its_bracket_fixes_the_digits() -> None:
    script = _script()
    m = MarginInterval(-0.1992, 0.3073, False, False, (-0.199198, -0.199202), (0.307285, 0.307287))
    assert script.interval(m) == "(−19.92 %, +30.73 %)"
    capped = MarginInterval(-0.3884, 10.0, False, True, (-0.38838, -0.38839), (10.0, 10.0))
    assert script.interval(capped) == "(−38.84 %, > +1000 %)"
    wide = MarginInterval(-0.1992, 0.3073, False, False, (-0.19918, -0.19935), (0.307285, 0.307287))
    with pytest.raises(SystemExit, match="more digits"):
        script.interval(wide)


def test_the_page_holds_the_three_blocks_and_no_old_margin() -> None:
    script = _script()
    text = script.PAGE.read_text(encoding="utf-8")
    assert sorted(script.page_blocks(text)) == ["pd-sweep", "predictor", "study"]
    # the margins main printed before the brackets (the unresolved boundary taken as unstable)
    for old in ("−19.90 %", "+30.71 %", "−36.32 %", "−9.13 %", "−19.06 %"):
        assert old not in text


def test_the_blocks_written_are_the_study_blocks_and_the_predictor_table(monkeypatch: pytest.MonkeyPatch) -> None:
    """``blocks()`` (what ``--write`` puts in the page) is the two study blocks and the predictor table, each
    computed below on its own (two tests, so that xdist runs them side by side)."""
    script = _script()
    monkeypatch.setattr(script, "study_blocks", lambda: ("the sweep", "the study"))
    monkeypatch.setattr(script, "predictor_block", lambda: "the predictor table")
    assert script.blocks() == {"pd-sweep": "the sweep", "predictor": "the predictor table", "study": "the study"}


@pytest.mark.slow
def test_the_page_predictor_table_equals_what_the_code_gives() -> None:
    script = _script()
    page = script.page_blocks(script.PAGE.read_text(encoding="utf-8"))
    computed = script.predictor_block()
    assert set(page) == {"pd-sweep", "predictor", "study"}
    assert page["predictor"] == computed
    # the bracketed boundary of the fast gains at 1 kHz, found independently in test_predictor_unresolved
    assert "| (−19.92 %, +30.73 %) |" in computed


@pytest.mark.slow
def test_the_page_study_tables_equal_what_the_code_gives() -> None:
    script = _script()
    page = script.page_blocks(script.PAGE.read_text(encoding="utf-8"))
    sweep, study = script.study_blocks()
    assert set(page) == {"pd-sweep", "predictor", "study"}
    assert page["pd-sweep"] == sweep
    assert page["study"] == study
