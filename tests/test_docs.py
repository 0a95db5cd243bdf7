"""The documentation: no raw Sphinx role and no ticket number in what a user reads; the strict site build."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

ROOT = Path(__file__).resolve().parents[1]
ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj):`")
# "issue 13", "ticket", "#12" used as a ticket number (not "#: " doc comments or "# " comments)
BOOKKEEPING = re.compile(r"\bissue\s*#?\d+|\bticket|(?<![\w&])#\d+\b", re.IGNORECASE)


def _sources() -> list[Path]:
    files = sorted((ROOT / "mrpctl").rglob("*.py"))
    return list(files)


def _hits(pattern: re.Pattern[str], files: list[Path]) -> list[str]:
    out = []
    for path in files:
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if pattern.search(line):
                out.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    return out


def test_no_sphinx_role_in_the_package_sources() -> None:
    files = _sources()
    assert len(files) > 30
    assert _hits(ROLE, files) == []


def test_no_ticket_number_in_what_users_read() -> None:
    files = [*_sources(), ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "design").glob("*.md")]
    files += [*(ROOT / "examples").rglob("*")]
    files = [p for p in files if p.is_file() and p.suffix in {".py", ".md", ".toml", ".txt", ""}]
    assert _hits(BOOKKEEPING, files) == []


def test_the_patterns_catch_what_they_are_for() -> None:
    assert ROLE.search("see :func:`simulate`") and not ROLE.search("see [`simulate`][mrpctl.simulation.simulate]")
    assert BOOKKEEPING.search('source="issue 13"') and BOOKKEEPING.search("fixed in #12")
    assert not BOOKKEEPING.search("#: a doc comment") and not BOOKKEEPING.search("&#39; x")


def _hook():
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_hook_rejects_a_rendered_role() -> None:
    pytest.importorskip("mkdocs")
    hook = _hook()
    page = SimpleNamespace(file=SimpleNamespace(src_uri="reference/x.md"))
    good = '<p>see <a href="#mrpctl.simulate"><code>simulate</code></a></p>'
    assert hook.on_post_page(good, page, None) == good
    for bad in ("<p>see :func:<code>simulate</code></p>", "<p>see :class:`Foo`</p>"):
        with pytest.raises(Exception, match="raw Sphinx role"):
            hook.on_post_page(bad, page, None)


@pytest.mark.slow
def test_the_strict_site_build_passes_and_holds_no_raw_role(tmp_path: Path) -> None:
    pytest.importorskip("mkdocstrings")
    site = tmp_path / "site"
    env = {"PYTHONPATH": str(ROOT), "NO_MKDOCS_2_WARNING": "1", "PATH": "/usr/bin:/bin"}
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    pages = list(site.rglob("*.html"))
    assert len(pages) > 30
    for module in ("flight", "predictor", "data", "errors", "campaign"):
        assert (site / "reference" / module).is_dir(), module
    raw = [str(p.relative_to(site)) for p in pages if ROLE.search(p.read_text(encoding="utf-8"))]
    assert raw == []


def _public_modules() -> list[str]:
    names = []
    for path in _sources():
        rel = path.relative_to(ROOT).with_suffix("").as_posix().replace("/", ".").removesuffix(".__init__")
        if not any(part.startswith("_") for part in rel.split(".")):
            names.append(rel)
    return names


def test_every_name_in_a_public_all_exists() -> None:
    import importlib

    checked = 0
    for name in _public_modules():
        module = importlib.import_module(name)
        for export in getattr(module, "__all__", ()):
            assert hasattr(module, export), f"{name}.__all__ names {export!r}, which it does not define"
            checked += 1
    assert checked > 200


def test_what_the_docs_import_is_public() -> None:
    import importlib

    texts = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "examples").rglob("*.py"))]
    imports = re.compile(r"from (mrpctl[\w.]*) import ([\w, ]+)")
    seen = 0
    for path in texts:
        for module_name, names in imports.findall(path.read_text(encoding="utf-8")):
            public = importlib.import_module(module_name).__all__
            for name in (n.strip() for n in names.split(",")):
                module = importlib.import_module(module_name)
                if name and not (hasattr(module, "__path__") and importlib.util.find_spec(f"{module_name}.{name}")):
                    # a submodule is public by its name; anything else must be in __all__
                    assert name in public, f"{path.relative_to(ROOT)} imports {module_name}.{name}, not in __all__"
                    seen += 1
    assert seen > 20


def test_every_public_module_has_a_reference_page():
    """Each module whose dotted name has no private part is rendered by a ``::: module`` line of docs/reference."""
    named: set[str] = set()
    for page in (ROOT / "docs" / "reference").rglob("*.md"):
        named |= set(re.findall(r"^::: *([\w.]+)", page.read_text(encoding="utf-8"), re.MULTILINE))
    public = []
    for path in sorted((ROOT / "mrpctl").rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        if parts[-1] == "__main__" or any(part.startswith("_") for part in parts):
            continue
        public.append(".".join(parts))
    assert [module for module in public if module not in named] == []
