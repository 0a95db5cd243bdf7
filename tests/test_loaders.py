"""Loaders of saved runs, scenario and campaign files and per-sample files: damaged, foreign and real-world
files are refused with one SpecificationError naming the file and the rule (never a library traceback)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from mrpctl import data, paper, simulate
from mrpctl.campaign import load_campaign
from mrpctl.errors import SpecificationError
from mrpctl.scenario import delay_sequence, load_scenario, samples_file
from mrpctl.switching import DelayAware

X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])


@pytest.fixture(scope="module")
def saved(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = simulate(paper.SPACECRAFT, paper.GAIN, X0, tau=0.5, rule=DelayAware(), t_final=2.0, rate=100.0)
    return data.save(run, tmp_path_factory.mktemp("run") / "run.nc", seed=1)


def _rewrite(saved: Path, target: Path, change) -> Path:  # type: ignore[no-untyped-def]
    with xr.open_dataset(saved, engine="scipy") as stored:
        dataset = stored.load()
    change(dataset)
    dataset.to_netcdf(target, engine="scipy", format="NETCDF3_64BIT")
    return target


def _set(name: str, value: object):  # type: ignore[no-untyped-def]
    def change(dataset: xr.Dataset) -> None:
        dataset[name] = value

    return change


def _attr(name: str, value: object):  # type: ignore[no-untyped-def]
    def change(dataset: xr.Dataset) -> None:
        dataset.attrs[name] = value

    return change


def test_saved_run_still_loads(saved: Path) -> None:
    back = data.load(saved)
    assert back.rate == 100.0 and back.tau == 0.5 and back.samples == 201


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        (_set("rate", -5.0), "rate must be > 0"),
        (_set("tau", -1.0), "tau must be >= 0"),
        (_set("tau", 0.505), "whole number"),
        (_set("rate", 50.0), "tau * rate"),  # delay_samples no longer matches
        (_set("substeps", 0), "substeps"),
        (_set("samples", 500), "samples = 500"),
        (_set("K", (("input", "state"), np.full((3, 6), np.nan))), "K must be finite"),
        (lambda d: d.__delitem__("sigma"), "the variable 'sigma' is missing"),
        (_attr("rule_parameter", "abc"), "rule_parameter must be a number"),
        (_attr("keep_every", "abc"), "keep_every"),
        (_attr("rule_type", "sideways"), "rule_type"),
        (_attr("versions", "{not json"), "versions"),
        (_attr("note", "x"), "'note' is not part of the format"),
    ],
)
def test_tampered_runs_are_refused(saved: Path, tmp_path: Path, change, needle: str) -> None:  # type: ignore[no-untyped-def]
    path = _rewrite(saved, tmp_path / "bad.nc", change)
    with pytest.raises(SpecificationError, match=r"is not a run as mrpctl\.data\.save writes it") as info:
        data.load(path)
    assert needle in str(info.value) and str(path) in str(info.value)


def test_truncated_garbled_and_foreign_files_are_refused(saved: Path, tmp_path: Path) -> None:
    raw = saved.read_bytes()
    (tmp_path / "half.nc").write_bytes(raw[: len(raw) // 2])
    garbled = bytearray(raw)
    garbled[10:40] = b"x" * 30
    (tmp_path / "garbled.nc").write_bytes(bytes(garbled))
    (tmp_path / "text.nc").write_text("hello\n")
    (tmp_path / "folder.nc").mkdir()
    for name, needle in (
        ("half.nc", "cannot be read"),
        ("garbled.nc", "cannot be read"),
        ("text.nc", "not a NetCDF-3 file"),
        ("folder.nc", "is a folder"),
    ):
        with pytest.raises(SpecificationError, match=needle) as info:
            data.load(tmp_path / name)
        assert name in str(info.value)
        if name in ("half.nc", "garbled.nc"):
            assert info.value.__cause__ is not None  # the reader's error, chained


# ------------------------------------------------------------------------------------ per-sample files
def test_csv_with_a_bom_is_read(tmp_path: Path) -> None:
    path = tmp_path / "w.csv"
    path.write_text("\ufeff0,0.5,0\n1,1,1\n", encoding="utf-8")
    assert samples_file(path, "torque_file").tolist() == [[0.0, 0.5, 0.0], [1.0, 1.0, 1.0]]


def test_nan_is_named_by_row_and_column(tmp_path: Path) -> None:
    rows = np.zeros((100, 3))
    rows[49, 1] = np.nan
    path = tmp_path / "w.csv"
    np.savetxt(path, rows, delimiter=",", header="t1,t2,t3")  # one comment line: data row 50 is line 51
    with pytest.raises(SpecificationError) as info:
        samples_file(path, "torque_file")
    message = str(info.value)
    assert "row 51, column 2" in message and "NaN" in message and "\n" not in message
    np.save(tmp_path / "w.npy", rows)
    with pytest.raises(SpecificationError, match="row 50, column 2"):
        samples_file(tmp_path / "w.npy", "torque_file")


def test_a_link_to_another_file_is_named_not_echoed(tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("SECRET password line\n")
    link = tmp_path / "w.csv"
    os.symlink(secret, link)
    with pytest.raises(SpecificationError) as info:
        samples_file(link, "torque_file")
    message = str(info.value)
    assert "SECRET" not in message and "secret.txt" in message and "row 1, column 1 is not a number" in message
    os.symlink(tmp_path / "gone.csv", tmp_path / "dangling.csv")
    with pytest.raises(SpecificationError, match="which does not exist"):
        samples_file(tmp_path / "dangling.csv", "torque_file")


def test_folder_and_non_utf8_files(tmp_path: Path) -> None:
    (tmp_path / "d.csv").mkdir()
    with pytest.raises(SpecificationError, match="is a folder"):
        samples_file(tmp_path / "d.csv", "sequence_file")
    (tmp_path / "l.csv").write_bytes("0,0,0\n# caf\xe9\n".encode("latin-1"))
    with pytest.raises(SpecificationError, match="not UTF-8 text: line 2, column 6"):
        samples_file(tmp_path / "l.csv", "torque_file")


def test_npy_header_is_read_before_the_data(tmp_path: Path) -> None:
    path = tmp_path / "huge.npy"
    with path.open("wb") as handle:
        np.lib.format.write_array_header_1_0(handle, {"descr": "<f8", "fortran_order": False, "shape": (10**10, 3)})
        handle.write(b"\0" * 240)
    with pytest.raises(SpecificationError, match=r"shape \(10000000000, 3\).*GB once read.*shorten the run"):
        samples_file(path, "torque_file")
    small = tmp_path / "short.npy"
    np.save(small, np.zeros((10, 3)))
    small.write_bytes(small.read_bytes()[:-8])
    with pytest.raises(SpecificationError, match="truncated"):
        samples_file(small, "torque_file")


def test_delays_written_as_k_h_are_whole_periods() -> None:
    delays = np.array([k * 0.1 for k in (1, 2, 3, 3, 1)])  # 3 * 0.1 = 0.30000000000000004
    model = delay_sequence(delays, "sequence_file", tau=0.3, rate=10.0)
    assert model.samples(10.0, 0, 5).tolist() == [1, 2, 3, 3, 1]
    with pytest.raises(SpecificationError, match=r"delay 3 of sequence_file \(counted from 1\)"):
        delay_sequence(np.array([0.1, 0.2, 0.4]), "sequence_file", tau=0.3, rate=10.0)


SCENARIO = """
tau = 0.3
rate = 10.0
t_final = 1.0
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -7.011
k_omega = -16.308
[initial]
sigma = [0.6, -0.2, 0.1]
omega = [0.3, 0.1, 0.0]
[rule]
type = "hysteretic"
[delay]
tau_min = 0.1
tau_max = 0.30000000000000004
"""


def test_scenario_tau_max_as_k_h_and_bom(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text("\ufeff" + SCENARIO, encoding="utf-8")
    scenario = load_scenario(path)
    assert scenario.delay is not None and scenario.delay.bounds(10.0) == (1, 3)


def test_campaign_file_not_utf8_or_a_folder(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_bytes(b"count = 1\n# caf\xe9\n")
    with pytest.raises(SpecificationError, match=r"c\.toml is not UTF-8 text.*line 2, column 6"):
        load_campaign(path)
    (tmp_path / "d.toml").mkdir()
    with pytest.raises(SpecificationError, match="is a folder"):
        load_campaign(tmp_path / "d.toml")
