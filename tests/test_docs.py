"""The documentation site: every ```python block runs, the pages link up, `mkdocs build --strict` passes."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md"))
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def _blocks(page: Path) -> list[str]:
    return BLOCK.findall(page.read_text(encoding="utf-8"))


PAGES_WITH_CODE = [p for p in PAGES if _blocks(p)]


def test_site_has_the_promised_pages() -> None:
    names = {p.relative_to(DOCS).as_posix() for p in PAGES}
    for page in (
        "index.md",
        "getting-started.md",
        "concepts/mrp-sets.md",
        "concepts/delay-and-sampling.md",
        "concepts/switching-rules.md",
        "how-to/design.md",
        "how-to/certify.md",
        "how-to/simulate.md",
        "how-to/campaigns.md",
        "how-to/export.md",
        "how-to/matlab.md",
        "how-to/interop.md",
        "reproduction.md",
        "reference/index.md",
    ):
        assert page in names, page
    assert len(PAGES_WITH_CODE) >= 10
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for page in names:
        assert page in nav, f"{page} is not in the mkdocs.yml nav"


def test_getting_started_commands_are_the_makefiles() -> None:
    text = (DOCS / "getting-started.md").read_text(encoding="utf-8")
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    for target in re.findall(r"^make (\w+)", text, re.M):
        assert re.search(rf"^{target}:", makefile, re.M), target


def test_images_exist() -> None:
    for page in PAGES:
        for link in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", page.read_text(encoding="utf-8")):
            assert (page.parent / link).read_bytes()[:4] == b"\x89PNG", f"{page.name}: {link}"


REPRODUCTION_PAGE = DOCS / "reproduction.md"


def _run_blocks(page: Path) -> None:
    namespace: dict[str, object] = {"__name__": "__docs__"}
    for i, code in enumerate(_blocks(page)):
        exec(compile(code, f"{page.relative_to(DOCS)}[block {i}]", "exec"), namespace)


@pytest.mark.parametrize(
    "page", [p for p in PAGES_WITH_CODE if p != REPRODUCTION_PAGE], ids=lambda p: p.relative_to(DOCS).as_posix()
)
def test_code_blocks_run(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The blocks of one page run in order in one namespace, in an empty folder; their asserts hold."""
    monkeypatch.chdir(tmp_path)
    _run_blocks(page)


def test_reproduction_page_blocks_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, paper_reproduction: tuple[Path, object]
) -> None:
    """The reproduction page's blocks, with ``reproduce()`` answering the session's reproduction (conftest)
    instead of computing the whole paper a second time; the page's own asserts check its numbers."""
    from mrpctl import reproduction

    _, computed = paper_reproduction
    monkeypatch.setattr(reproduction, "reproduce", lambda *args, **kwargs: computed)
    monkeypatch.chdir(tmp_path)
    assert REPRODUCTION_PAGE in PAGES_WITH_CODE
    _run_blocks(REPRODUCTION_PAGE)


@pytest.mark.slow
def test_mkdocs_build_strict(tmp_path: Path) -> None:
    mkdocs = Path(sys.executable).with_name("mkdocs")
    if not mkdocs.exists():
        found = shutil.which("mkdocs")
        if found is None:
            pytest.skip("mkdocs is not installed (test extra)")
        mkdocs = Path(found)
    site = tmp_path / "site"
    completed = subprocess.run(
        [str(mkdocs), "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert (site / "index.html").exists()
    api = (site / "reference" / "interop" / "index.html").read_text(encoding="utf-8")
    assert "basilisk_mrp_feedback" in api and "delayed_loop" in api
    assert (site / "gallery" / "fig7_boundary_layer.png").exists()
