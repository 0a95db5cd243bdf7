"""The package's imports run one way (design/architecture.md): read from the sources with `ast`.

Every import of an mrpctl module counts, wherever it stands (top level, inside a function, under
``if TYPE_CHECKING``), so a circle cannot hide in a deferred or a type-only import. The checks:

* every module belongs to one layer of `LAYERS` and imports only from its own layer or lower ones;
* no import circle (a strongly connected component of more than one module);
* no private name (``_name``) imported from another module, and no private module of another package;
* ``from mrpctl import X`` only for subpackages and modules (never a name re-exported by the root,
  which would be an import of everything);
* an import inside a function only where it defers a heavy dependency, with a ``# deferred:`` comment
  on the line before it (or before the block of imports it heads) saying what it defers.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "mrpctl"

#: The layers, lowest first: a module imports from its own layer or a lower one only.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    (
        "values and kinematics",
        (
            "mrpctl.errors",
            "mrpctl._validation",
            "mrpctl.mrp",
            "mrpctl.spacecraft",
            "mrpctl.conventions",
            "mrpctl.claims",
            "mrpctl.provenance",
            "mrpctl._compile",
            "mrpctl._files",
        ),
    ),
    (
        "plant and flight-loop models",
        (
            "mrpctl.model",
            "mrpctl.wheels",
            "mrpctl.switching",
            "mrpctl.flight",
            "mrpctl.clock",
            "mrpctl.paper",
            "mrpctl.estimation",
            "mrpctl.guidance",
        ),
    ),
    ("linear analysis and synthesis", ("mrpctl.design",)),
    ("the predictor and the rules by name", ("mrpctl.predictor", "mrpctl.rules")),
    ("the closed loop as CasADi Functions", ("mrpctl.loop",)),
    ("engines", ("mrpctl.engines",)),
    ("figures", ("mrpctl._plots_common", "mrpctl._plots_pointing", "mrpctl.plots")),
    ("simulate and its results", ("mrpctl.simulation",)),
    (
        "files and bridges",
        (
            "mrpctl.scenario",
            "mrpctl._scenario_tables",
            "mrpctl._scenario_wheels",
            "mrpctl._scenario_estimator",
            "mrpctl._scenario_steering",
            "mrpctl.data",
            "mrpctl.interop",
            "mrpctl._export",
            "mrpctl._publish",
        ),
    ),
    ("campaigns and studies", ("mrpctl.campaign", "mrpctl._predictor_study", "mrpctl.reproduction")),
    ("command line", ("mrpctl.cli", "mrpctl.__main__")),
)

#: Third-party modules heavy enough to be imported only where they are used (each with a comment).
HEAVY = {"cvxpy", "xarray", "zarr", "pandas", "matplotlib", "control", "dask", "distributed", "Basilisk"}
#: mrpctl modules that import a heavy dependency at their top, and so may be imported where they are used:
#: the figures (matplotlib), the campaign store, runner and report (xarray, zarr, Dask, matplotlib) and the
#: python-control bridge.
HEAVY_OWN = {
    "mrpctl.plots",
    "mrpctl._plots_common",
    "mrpctl._plots_pointing",
    "mrpctl.campaign.run",
    "mrpctl.campaign.store",
    "mrpctl.campaign.report",
    "mrpctl.campaign.trajectories",
    "mrpctl.interop",
}


def _module(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module(path): path for path in PACKAGE.rglob("*.py")}


def _layer(module: str) -> int:
    for index, (_, prefixes) in enumerate(LAYERS):
        if any(module == prefix or module.startswith(prefix + ".") for prefix in prefixes):
            return index
    raise AssertionError(f"{module} is in no layer of tests/test_architecture.py: place it in LAYERS")


def _target(name: str) -> str:
    while name not in MODULES and "." in name:
        name = name.rpartition(".")[0]
    return name


def _imports() -> list[dict]:
    """One row per imported mrpctl name: importer, target module, name, line, inside a function, deferred."""
    rows = []
    for module, path in sorted(MODULES.items()):
        source = path.read_text(encoding="utf-8")
        lines = source.splitlines()
        tree = ast.parse(source, str(path))
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        in_function = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                in_function.update(id(sub) for sub in ast.walk(node) if isinstance(sub, ast.Import | ast.ImportFrom))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                pairs = [(alias.name, None) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    stem = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    base = ".".join([*stem, *([node.module] if node.module else [])])
                pairs = [(f"{base}.{alias.name}", None) if f"{base}.{alias.name}" in MODULES else (base, alias.name)
                         for alias in node.names]  # fmt: skip
            else:
                continue
            above = node.lineno - 2  # the comment may head a block of consecutive deferred imports
            while above > 0 and lines[above].strip().startswith(("import ", "from ")):
                above -= 1
            comment = lines[above].strip() if above >= 0 else ""
            for name, imported in pairs:
                top = name.split(".")[0]
                rows.append(
                    {
                        "importer": module,
                        "target": _target(name) if top == "mrpctl" else name,
                        "own": top == "mrpctl",
                        "name": imported,
                        "line": node.lineno,
                        "hidden": id(node) in in_function,
                        "deferred": comment.startswith("# deferred:"),
                    }
                )
    return rows


IMPORTS = _imports()
OWN = [row for row in IMPORTS if row["own"] and row["target"] != row["importer"]]


def test_every_module_has_a_layer_and_imports_only_downwards():
    upward = []
    for row in OWN:
        if "mrpctl" in (row["target"], row["importer"]):
            continue  # the root re-exports the public API; `from mrpctl import X` is checked below
        if _layer(row["target"]) > _layer(row["importer"]):
            upward.append(f"{row['importer']}:{row['line']} -> {row['target']}")
    assert upward == []


def test_no_import_circle():
    graph: dict[str, set[str]] = {module: set() for module in MODULES if module != "mrpctl"}
    for row in OWN:
        if row["target"] != "mrpctl" and row["importer"] != "mrpctl":
            graph[row["importer"]].add(row["target"])
    # a package's __init__ importing its own submodules (re-exports) is no design circle: leave those edges out
    for module, targets in graph.items():
        graph[module] = {t for t in targets if not t.startswith(module + ".")}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []

    def visit(node: str) -> None:  # Tarjan's strongly connected components
        index[node] = low[node] = len(index)
        stack.append(node)
        for target in graph[node]:
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    assert circles == []


def test_no_private_name_or_module_of_another_package_is_imported():
    reaches = []
    for row in OWN:
        name = row["name"]
        private = bool(name) and name.startswith("_") and not name.startswith("__")
        if private and f"{row['target']}.{name}" not in MODULES:  # a private name, not a private submodule
            reaches.append(f"{row['importer']}:{row['line']} imports {row['target']}.{name}")
        parts = row["target"].split(".")
        for i, part in enumerate(parts):
            if part.startswith("_") and not part.startswith("__"):
                owner = ".".join(parts[:i])
                importer = row["importer"]
                if not (importer == owner or importer.startswith(owner + ".")):
                    reaches.append(f"{importer}:{row['line']} imports the private module {row['target']}")
                break
    assert reaches == []


def test_the_package_root_is_imported_for_its_modules_only():
    through_root = [
        f"{row['importer']}:{row['line']} imports {row['name']} from mrpctl"
        for row in OWN
        if row["target"] == "mrpctl" and row["importer"] not in ("mrpctl", "mrpctl.__main__")
    ]
    assert through_root == []


def test_imports_inside_functions_only_defer_heavy_dependencies_and_say_so():
    hidden = []
    for row in IMPORTS:
        if not row["hidden"]:
            continue
        heavy = (row["target"] in HEAVY_OWN) if row["own"] else row["target"].split(".")[0] in HEAVY
        if not (heavy and row["deferred"]):
            hidden.append(f"{row['importer']}:{row['line']} -> {row['target']}")
    assert hidden == []


@pytest.mark.parametrize("module", sorted(m for m in MODULES if not any(p.startswith("_") for p in m.split("."))))
def test_every_public_module_declares_its_api(module):
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    declared = [
        node
        for node in tree.body
        if isinstance(node, ast.Assign | ast.AnnAssign)
        and any(
            isinstance(t, ast.Name) and t.id == "__all__"
            for t in getattr(node, "targets", [getattr(node, "target", None)])
        )
    ]
    assert declared, f"{module} has no __all__"
