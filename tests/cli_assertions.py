"""Assertions shared by the CLI tests."""

from __future__ import annotations

import pytest


def one_line_error(capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    """The captured stderr, asserted to be one ``mrpctl: error:`` line (no traceback) containing every needle."""
    err = capsys.readouterr().err
    assert err.startswith("mrpctl: error:"), err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err
