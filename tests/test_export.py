"""mrpctl.export: round trips of the .casadi files and the shared library, manifest, C harness, bad input."""

from __future__ import annotations

import hashlib
import json
import os
import runpy
import shutil
import subprocess
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import mrpctl
from mrpctl import _export as export_module
from mrpctl import closed_loop_functions, paper, simulate
from mrpctl._compile import CompilerWarning, find_compiler
from mrpctl._export import (
    C_PREFIX,
    EXPORTED_FUNCTIONS,
    HEADER_NAME,
    LIBRARY_NAME,
    MANIFEST_NAME,
    SOURCE_NAME,
    ExportResult,
    export,
)
from mrpctl.errors import CodegenError, SpecificationError
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import DelayAware, NoSwitching, OnDelayed

ROOT = Path(__file__).resolve().parents[1]
HARNESS = ROOT / "examples" / "export_harness.c"
HAS_COMPILER = find_compiler() is not None
needs_compiler = pytest.mark.skipif(not HAS_COMPILER, reason="no C compiler on this machine")

# The paper's case, with OnDelayed: over the first second it does switch (from t = 0.944 s,
# once the delayed measurement shows |sigma| >= 1), so the harness exercises the rule Function.
PAPER = dict(spacecraft=paper.SPACECRAFT, K=paper.GAIN, tau=paper.TAU, rule=OnDelayed(), rate=1000.0)
# A second, smaller case: full inertia, a random-ish gain, memory and a parameter in the rule.
OTHER = dict(
    spacecraft=Spacecraft([[12.0, 0.5, -0.3], [0.5, 9.0, 0.2], [-0.3, 0.2, 7.0]]),
    K=np.hstack((-3.0 * np.eye(3) + 0.1, -8.0 * np.eye(3))),
    tau=0.02,
    rule=DelayAware(alpha=1.1),
    rate=200.0,
    substeps=3,
)


def _export(folder: Path, case: dict, **options) -> ExportResult:
    args = {key: value for key, value in case.items() if key not in ("spacecraft", "K")}
    return export(case["spacecraft"], case["K"], folder, **args, **options)


@pytest.fixture(scope="module")
def paper_export(tmp_path_factory) -> ExportResult:
    return _export(tmp_path_factory.mktemp("export") / "paper", PAPER)


@pytest.fixture(scope="module")
def other_export(tmp_path_factory) -> ExportResult:
    return _export(tmp_path_factory.mktemp("export") / "other", OTHER)


def _closed(case: dict):
    args = {key: value for key, value in case.items() if key not in ("spacecraft", "K")}
    return closed_loop_functions(case["spacecraft"], case["K"], **args)


def _random_inputs(function: ca.Function, rng: np.random.Generator) -> list[np.ndarray]:
    """Random inputs; states with |sigma| around 1 so that the rules take both branches."""
    inputs = []
    for i in range(function.n_in()):
        rows, columns = function.size_in(i)
        value = rng.normal(scale=0.6, size=(rows, columns))
        if function.name_in(i) == "memory":
            value = rng.integers(0, 6, size=(rows, columns)).astype(float)
        inputs.append(value)
    return inputs


def _max_difference(reference: ca.Function, other: ca.Function, rng: np.random.Generator, draws: int) -> float:
    worst = 0.0
    for _ in range(draws):
        inputs = _random_inputs(reference, rng)
        expected = reference.call(inputs)
        found = other.call(inputs)
        for a, b in zip(expected, found, strict=True):
            a, b = np.asarray(a), np.asarray(b)
            assert a.shape == b.shape
            assert np.all(np.isfinite(a))
            worst = max(worst, float(np.max(np.abs(a - b))))
    return worst


# =================================================================== files and round trips
def test_folder_holds_the_promised_files(paper_export):
    folder = paper_export.folder
    expected = {f"{name}.casadi" for name in EXPORTED_FUNCTIONS}
    expected |= {SOURCE_NAME, HEADER_NAME, MANIFEST_NAME} | ({LIBRARY_NAME} if HAS_COMPILER else set())
    assert {path.name for path in folder.iterdir()} == expected
    assert {path.name for path in paper_export.files} == expected
    assert paper_export.files[-1].name == MANIFEST_NAME
    if HAS_COMPILER:
        assert paper_export.library == folder / LIBRARY_NAME
        assert paper_export.compiled and paper_export.skipped_reason is None
    header = (folder / HEADER_NAME).read_text()
    for name in ("dynamics", "controller", "rule", "step", "chunk"):
        assert f"int {C_PREFIX}{name}(const casadi_real** arg" in header
        assert f"#define {C_PREFIX}{name}_SZ_W" in header
    text = str(paper_export)
    assert str(folder) in text and LIBRARY_NAME in text and "OnDelayed" in text and "500 samples" in text


@pytest.mark.parametrize("case_fixture", ["paper_export", "other_export"])
def test_casadi_files_round_trip(case_fixture, request, rng):
    result = request.getfixturevalue(case_fixture)
    case = PAPER if case_fixture == "paper_export" else OTHER
    for name, function in _closed(case).functions().items():
        if name not in EXPORTED_FUNCTIONS:
            continue
        loaded = ca.Function.load(str(result.folder / f"{name}.casadi"))
        assert loaded.name() == function.name()
        assert loaded.name_in() == function.name_in() and loaded.name_out() == function.name_out()
        draws = 3 if name == "chunk" else 25
        assert _max_difference(function, loaded, rng, draws) <= 1e-15, name


@needs_compiler
@pytest.mark.parametrize("case_fixture", ["paper_export", "other_export"])
def test_shared_library_round_trip(case_fixture, request, rng):
    result = request.getfixturevalue(case_fixture)
    case = PAPER if case_fixture == "paper_export" else OTHER
    for name, function in _closed(case).functions().items():
        if name not in EXPORTED_FUNCTIONS:
            continue
        external = ca.external(C_PREFIX + name, str(result.library))
        assert external.name_in() == function.name_in() and external.name_out() == function.name_out()
        draws = 3 if name == "chunk" else 25
        assert _max_difference(function, external, rng, draws) <= 1e-15, name


def test_rule_inputs_take_both_branches(paper_export, rng):
    """The random inputs of the round trips do exercise switching and not switching."""
    rule = ca.Function.load(str(paper_export.folder / "rule.casadi"))
    flags = [float(rule.call(_random_inputs(rule, rng))[2]) for _ in range(25)]
    assert 0.0 in flags and 1.0 in flags


# ============================================================================== manifest
@pytest.mark.parametrize("case_fixture", ["paper_export", "other_export"])
def test_manifest_content(case_fixture, request):
    result = request.getfixturevalue(case_fixture)
    case = PAPER if case_fixture == "paper_export" else OTHER
    closed = _closed(case)
    manifest = json.loads((result.folder / MANIFEST_NAME).read_text())
    assert manifest == result.manifest
    assert manifest["mrpctl_version"] == mrpctl.__version__
    assert manifest["casadi_version"] == ca.__version__
    parameters = manifest["parameters"]
    assert parameters["tau"] == case["tau"] and parameters["rate"] == case["rate"]
    assert parameters["delay_samples"] == round(case["tau"] * case["rate"]) == closed.delay_samples
    assert parameters["substeps"] == case.get("substeps", 1)
    assert np.array_equal(parameters["K"], np.asarray(case["K"], dtype=float))
    assert np.array_equal(parameters["J"], case["spacecraft"].inertia)
    rule = case["rule"]
    assert parameters["rule"] == {
        "class": type(rule).__name__,
        "label": rule.label,
        "str": str(rule),
        "parameters": list(rule.parameters()),
    }
    assert parameters["initial_memory"] == rule.initial_memory(delay_samples=closed.delay_samples)
    assert list(manifest["functions"]) == list(EXPORTED_FUNCTIONS)
    for name, entry in manifest["functions"].items():
        function = closed.functions()[name]
        assert entry["file"] == f"{name}.casadi" and entry["c_symbol"] == C_PREFIX + name
        assert [port["name"] for port in entry["inputs"]] == function.name_in()
        assert [port["name"] for port in entry["outputs"]] == function.name_out()
        assert [tuple(port["shape"]) for port in entry["inputs"]] == [
            function.size_in(i) for i in range(function.n_in())
        ]
        assert [tuple(port["shape"]) for port in entry["outputs"]] == [
            function.size_out(i) for i in range(function.n_out())
        ]
    d = closed.delay_samples
    chunk = manifest["functions"]["chunk"]
    assert chunk["inputs"][2] == {"name": "history", "shape": [6, max(d, 1)]}
    assert manifest["c"]["library"] == (LIBRARY_NAME if HAS_COMPILER else None)
    assert (manifest["c"]["library_skipped_reason"] is None) == HAS_COMPILER
    assert manifest["c"]["flags"] == ["-O2", "-shared", "-fPIC", "-lm"]  # IEEE-exact: no fast-math


def test_manifest_hash_covers_every_other_file(paper_export):
    folder = paper_export.folder
    manifest = paper_export.manifest
    names = sorted(path.name for path in folder.iterdir() if path.name != MANIFEST_NAME)
    digests = {name: hashlib.sha256((folder / name).read_bytes()).hexdigest() for name in names}
    assert manifest["files"] == digests
    listing = "".join(f"{digests[name]}  {name}\n" for name in names)  # the text of `sha256sum`
    assert manifest["content_hash"]["value"] == hashlib.sha256(listing.encode()).hexdigest()
    assert paper_export.content_hash == manifest["content_hash"]["value"]


def test_export_is_deterministic(paper_export, tmp_path):
    again = _export(tmp_path / "again", PAPER, compile=False)
    for name in [f"{name}.casadi" for name in EXPORTED_FUNCTIONS] + [SOURCE_NAME, HEADER_NAME]:
        assert again.manifest["files"][name] == paper_export.manifest["files"][name], name


# ============================================================================= C harness
@needs_compiler
def test_c_harness_matches_simulate(paper_export, tmp_path):
    lines = HARNESS.read_text().splitlines()
    assert 20 <= len(lines) <= 40
    binary = tmp_path / "harness"
    folder = paper_export.folder
    build = [find_compiler(), "-O2", "-I", str(folder), str(HARNESS), str(folder / SOURCE_NAME), "-o"]
    done = subprocess.run([*build, str(binary), "-lm"], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    parameters = paper_export.manifest["parameters"]
    x0 = np.asarray(paper.INITIAL_STATE)
    arguments = [str(parameters["delay_samples"]), "1000", *(repr(float(value)) for value in x0)]
    arguments.append(repr(parameters["initial_memory"]))
    run = subprocess.run([str(binary), *arguments], capture_output=True, text=True, check=True, timeout=60)
    final = np.array([float(value) for value in run.stdout.split()])
    assert final.shape == (6,)

    reference = simulate(paper.SPACECRAFT, paper.GAIN, x0, tau=paper.TAU, rule=OnDelayed(), t_final=1.0)
    assert reference.t[-1] == 1.0 and reference.switch_count > 0  # the rule did act
    expected = np.concatenate((reference.sigma[-1], reference.omega[-1] / 4.0))
    assert np.max(np.abs(final - expected)) <= 1e-12


# ============================================================================= bad input
def test_non_empty_folder_is_refused_and_overwrite_replaces(tmp_path):
    folder = tmp_path / "busy"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(SpecificationError, match=r"out_dir .*busy.* is not empty.*overwrite=True"):
        _export(folder, OTHER, compile=False)
    assert sorted(path.name for path in folder.iterdir()) == ["notes.txt"]

    first = _export(folder, OTHER, overwrite=True)
    assert (folder / "notes.txt").read_text() == "mine"  # files not ours are kept
    second = _export(folder, OTHER, overwrite=True, compile=False)
    assert first.compiled == (find_compiler() is not None)
    assert not (folder / LIBRARY_NAME).exists()  # the stale library of the first export is gone
    assert second.library is None and second.skipped_reason == "compile=False was given"
    assert LIBRARY_NAME not in second.manifest["files"]
    assert first.manifest["files"][SOURCE_NAME] == second.manifest["files"][SOURCE_NAME]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(path.relative_to(folder)): path.read_bytes() for path in sorted(folder.rglob("*")) if path.is_file()}


def _raise(error: BaseException):
    def fail(*args, **kwargs):
        raise error

    return fail


def _fail_on_second_rename(monkeypatch):
    calls = []
    original = os.rename

    def rename(source, destination):
        calls.append(source)
        if len(calls) == 2:  # the old folder is aside; putting the new one in fails
            raise OSError(28, "No space left on device")
        original(source, destination)

    monkeypatch.setattr(export_module.os, "rename", rename)


@pytest.mark.parametrize(
    "failure",
    ["write_c_code", "manifest_interrupted", "second_rename"],
)
def test_interrupted_overwrite_keeps_the_old_export(failure, paper_export, tmp_path, monkeypatch):
    folder = tmp_path / "previous"
    shutil.copytree(paper_export.folder, folder)  # a whole export, with its library when there is a compiler
    (folder / "notes.txt").write_text("mine")
    (folder / "plots").mkdir()
    (folder / "plots" / "a.txt").write_text("also mine")
    before = _snapshot(folder)
    if failure == "write_c_code":
        monkeypatch.setattr(export_module, "_write_c_code", _raise(CodegenError("cannot write: disk full")))
        expected: type[BaseException] = CodegenError
    elif failure == "manifest_interrupted":  # Ctrl-C once every other file is written
        monkeypatch.setattr(export_module, "_manifest", _raise(KeyboardInterrupt()))
        expected = KeyboardInterrupt
    else:
        _fail_on_second_rename(monkeypatch)
        expected = CodegenError
    with pytest.raises(expected):
        _export(folder, OTHER, overwrite=True, compile=False)
    assert _snapshot(folder) == before  # the old export and the user's files, byte for byte
    assert sorted(path.name for path in tmp_path.iterdir()) == ["previous"]  # no temporary folder left


def test_overwrite_swaps_the_folder_and_carries_other_files_over(tmp_path):
    folder = tmp_path / "out"
    first = _export(folder, OTHER, compile=False)
    (folder / "notes.txt").write_text("mine")
    (folder / "plots").mkdir()
    (folder / "plots" / "a.txt").write_text("also mine")
    (folder / "link").symlink_to("notes.txt")
    folder.chmod(0o750)
    second = _export(folder, PAPER, overwrite=True, compile=False)
    assert (folder / "notes.txt").read_text() == "mine" and (folder / "plots" / "a.txt").read_text() == "also mine"
    assert os.readlink(folder / "link") == "notes.txt"
    assert (folder.stat().st_mode & 0o777) == 0o750
    assert second.manifest["parameters"]["tau"] == PAPER["tau"] != first.manifest["parameters"]["tau"]
    assert json.loads((folder / MANIFEST_NAME).read_text()) == second.manifest
    assert sorted(path.name for path in tmp_path.iterdir()) == ["out"]


def test_leftovers_of_a_killed_export_are_cleaned_or_restored(tmp_path):
    dead = subprocess.Popen(["true"])
    dead.wait()
    folder = tmp_path / "out"
    staging = tmp_path / f".out.export-{dead.pid}-0a1b2c3d"  # killed while writing
    staging.mkdir()
    (staging / "step.casadi").write_text("half")
    aside = tmp_path / f".out.replaced-{dead.pid}-0a1b2c3d"  # killed between the two renames
    aside.mkdir()
    (aside / MANIFEST_NAME).write_text("{}")
    with pytest.raises(SpecificationError, match="is not empty"):  # the old export is back: not replaced
        _export(folder, OTHER, compile=False)
    assert sorted(path.name for path in tmp_path.iterdir()) == ["out"]
    assert (folder / MANIFEST_NAME).read_text() == "{}"


def test_export_into_the_working_directory(tmp_path, monkeypatch):
    """The current directory cannot be renamed away: its files are replaced one by one, the manifest last."""
    folder = tmp_path / "here"
    _export(folder, OTHER, compile=False)
    (folder / "notes.txt").write_text("mine")
    monkeypatch.chdir(folder)
    result = _export(Path("."), PAPER, overwrite=True, compile=False)
    assert Path.cwd() == folder.resolve() and (Path(".") / "notes.txt").read_text() == "mine"
    assert json.loads(Path(MANIFEST_NAME).read_text()) == result.manifest
    names = {path.name for path in folder.iterdir()}
    assert names == {path.name for path in result.files} | {"notes.txt"}  # no staging folder left


def test_overwrite_through_a_symbolic_link_keeps_the_link(tmp_path):
    real = tmp_path / "real"
    _export(real, OTHER, compile=False)
    link = tmp_path / "link"
    link.symlink_to(real)
    result = _export(link, PAPER, overwrite=True, compile=False)
    assert link.is_symlink() and result.folder == link
    assert json.loads((real / MANIFEST_NAME).read_text())["parameters"]["tau"] == PAPER["tau"]


def test_unwritable_folder(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    with pytest.raises(CodegenError, match=r"out_dir .*a_file/export"):
        _export(blocker / "export", OTHER, compile=False)
    with pytest.raises(SpecificationError, match=r"out_dir .*a_file.* is not a folder"):
        _export(blocker, OTHER, compile=False)


def test_invalid_loop_is_refused_before_writing(tmp_path):
    folder = tmp_path / "never"
    with pytest.raises(SpecificationError, match="tau"):
        export(paper.SPACECRAFT, paper.GAIN, folder, tau=0.0005, rule=OnDelayed(), rate=1000.0 / 3)
    with pytest.raises(SpecificationError, match="overwrite"):
        export(paper.SPACECRAFT, paper.GAIN, folder, tau=0.5, rule=OnDelayed(), overwrite="yes")
    assert not folder.exists()


def test_no_compiler_writes_sources_and_warns(tmp_path, monkeypatch):
    monkeypatch.setattr(export_module, "find_compiler", lambda: None)
    with pytest.warns(CompilerWarning, match="no C compiler found"):
        result = _export(tmp_path / "nocc", OTHER)
    assert result.library is None and not result.compiled
    assert "no C compiler found" in result.skipped_reason and LIBRARY_NAME in result.skipped_reason
    names = {path.name for path in result.folder.iterdir()}
    assert LIBRARY_NAME not in names
    assert {SOURCE_NAME, HEADER_NAME, MANIFEST_NAME, "step.casadi", "chunk.casadi"} <= names
    assert result.manifest["c"]["library"] is None
    assert result.manifest["c"]["library_skipped_reason"] == result.skipped_reason
    assert "not built: no C compiler found" in str(result)


def test_compile_false_does_not_warn(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error", CompilerWarning)
        result = _export(tmp_path / "nolib", OTHER, compile=False)
    assert result.library is None and not (result.folder / LIBRARY_NAME).exists()


# =============================================================================== example
@needs_compiler
def test_python_example_runs(capsys):
    runpy.run_path(str(ROOT / "examples" / "export_and_call.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "using libmrpctl_model.so: mrpctl_step:(x[6],u[3])->(x_next[6])" in out
    sigma = np.array(out.split("sigma = [")[1].split("]")[0].split(), dtype=float)
    reference = simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        paper.INITIAL_STATE,
        tau=paper.TAU,
        rule=NoSwitching(),
        t_final=1.0,
    )
    assert np.allclose(sigma, reference.sigma[-1], rtol=0, atol=1e-7)  # printed with numpy's 8 digits
