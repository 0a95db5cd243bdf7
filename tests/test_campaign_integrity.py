"""Campaign store integrity: damaged chunks found by report/replay and repaired by resume, one writer, strict JSON."""

from __future__ import annotations

import copy
import fcntl
import json
import multiprocessing
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mrpctl.campaign import parse_campaign, replay, report, run_campaign, write_report
from mrpctl.campaign.integrity import LOCK_NAME, StoreDamagedError, StoreLockedError, writer_lock
from mrpctl.campaign.run import campaign_token, task_key
from mrpctl.campaign.store import STORE_NAME

SPEC = {
    "name": "tiny",
    "count": 12,
    "seed": 5,
    "tau": 0.05,
    "rate": 100.0,
    "t_final": 1.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"k_sigma": -70.11, "k_omega": -163.08},
    "rule": {"type": "delay-aware"},
    "dispersions": {"attitude": {"angle_deg": [150.0, 180.0]}, "omega": {"magnitude": [0.0, 0.5]}},
}
CHUNK = 4


def _tree(out: Path) -> dict[str, bytes]:
    store = out / STORE_NAME
    return {str(p.relative_to(store)): p.read_bytes() for p in sorted(store.rglob("*")) if p.is_file()}


def _strict(text: str):
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    out = tmp_path_factory.mktemp("clean")
    result = run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=CHUNK, threads=1)
    assert result.complete and result.verified
    return out


def _damage(path: Path, how: str) -> None:
    if how == "delete":
        path.unlink()
    elif how == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    else:
        data = bytearray(path.read_bytes())
        data[len(data) // 2] ^= 0x01
        path.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["delete", "truncate", "flip"])
@pytest.mark.parametrize(("array", "key"), [("max_sigma", "c/1"), ("sigma0", "c/1/0")])
def test_damaged_chunk_is_detected_by_report_and_replay_and_repaired_by_resume(clean, tmp_path, array, key, how):
    out = tmp_path / "out"
    shutil.copytree(clean, out)
    _damage(out / STORE_NAME / array / key, how)
    with pytest.raises(StoreDamagedError) as caught:
        report(out)
    message = str(caught.value)
    assert str(out / STORE_NAME) in message and f"array {array}" in message and "runs 4-7" in message
    assert f"mrpctl campaign run CAMPAIGN.toml --out {out}" in message
    assert {"delete": "is missing", "truncate": "bytes", "flip": "changed bytes"}[how] in message
    # the intact runs are reported, the damaged chunk listed
    partial = report(out, intact_only=True)
    assert partial.complete == 8 and [d["runs"] for d in partial.integrity["damaged"]] == [[4, 7]]
    assert "LEFT OUT (runs 4-7)" in str(partial)
    assert replay(out, 0).matches  # another chunk's damage does not stop a replay
    # a run of the damaged chunk: refused when the chunk cannot be decoded, else compared and marked damaged
    try:
        result = replay(out, 5)
    except StoreDamagedError as exc:
        assert "runs 4-7" in str(exc) and array in str(exc)
    else:
        assert result.damage is not None and "runs 4-7" in result.damage and "DAMAGED" in str(result)
    # resume re-runs exactly that chunk, says which, and the store equals the clean one bit for bit
    resumed = run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, threads=1)
    assert resumed.simulated == 1 and resumed.runs == 4 and len(resumed.repaired) == 1
    assert "runs 4-7" in resumed.repaired[0] and array in resumed.repaired[0]
    assert "re-ran 1 damaged chunk(s)" in str(resumed)
    assert _tree(out) == _tree(clean)
    assert report(out).complete == 12


def test_missing_record_or_flag_is_damage_and_an_interrupted_record_is_rerun(clean, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(clean, out)
    (out / STORE_NAME / "chunk_complete" / "sha256" / "000002.json").unlink()
    with pytest.raises(StoreDamagedError, match=r"chunk 2 \(runs 8-11\).*checksum record\) is missing"):
        report(out)
    resumed = run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, threads=1)
    assert resumed.simulated == 1 and "runs 8-11" in resumed.repaired[0]
    assert _tree(out) == _tree(clean)
    (out / STORE_NAME / "chunk_complete" / "c" / "0").unlink()  # the flag of a recorded chunk
    with pytest.raises(StoreDamagedError, match=r"chunk 0 \(runs 0-3\), array chunk_complete"):
        report(out)
    run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, threads=1)
    assert _tree(out) == _tree(clean)


def test_a_store_without_records_is_read_with_a_note(clean, tmp_path):
    """A store of an older mrpctl (no checksum records) is reported, marked as not verified, and resumed."""
    out = tmp_path / "out"
    shutil.copytree(clean, out)
    shutil.rmtree(out / STORE_NAME / "chunk_complete" / "sha256")
    result = report(out)
    assert result.complete == 12 and result.integrity["verified"] is False
    assert "NOT VERIFIED" in str(result)
    again = run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, threads=1)
    assert not again.verified and "not verified" in str(again)


def test_summary_json_is_strict_json_with_nulls(tmp_path):
    """No run settles within 0.2 s: the settling quantiles are NaN in memory and null in summary.json."""
    spec = copy.deepcopy(SPEC)
    spec["t_final"] = 0.2
    out = tmp_path / "out"
    run_campaign(parse_campaign(spec), out, chunk=CHUNK, threads=1)
    result, _paths = write_report(out)
    assert result.converged == 0
    summary = _strict((out / "report" / "summary.json").read_text())
    assert summary["settling_time_s"] == {"median": None, "p95": None, "max": None}
    assert summary["integrity"] == {"damaged": [], "verified": True}
    for record in (out / STORE_NAME / "chunk_complete" / "sha256").iterdir():
        _strict(record.read_text())


def test_task_keys_differ_per_campaign_store_and_attempt(tmp_path):
    a = parse_campaign(copy.deepcopy(SPEC))
    other = copy.deepcopy(SPEC)
    other["seed"] = 6
    b = parse_campaign(other)
    tokens = {campaign_token(a, tmp_path / "x"), campaign_token(b, tmp_path / "x"), campaign_token(a, tmp_path / "y")}
    assert len(tokens) == 3 and campaign_token(a, tmp_path / "x") == campaign_token(a, tmp_path / "x")
    token = campaign_token(a, tmp_path / "x")
    assert task_key(token, "0001", 3) != task_key(token, "0002", 3)
    assert task_key(token, "0001", 3).rsplit("-", 1)[1] == "3"


# -- one writer -------------------------------------------------------------------------------------------------


def _hold(out: str, ready, release) -> None:  # a child that holds the lock until told
    with writer_lock(out):
        ready.set()
        release.wait(30)


def _writer(out: str, go, results) -> None:  # a child campaign writer started together with another
    go.wait(30)
    try:
        result = run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=CHUNK, threads=1)
        results.put(("ran", result.simulated))
    except StoreLockedError as exc:
        results.put(("locked", str(exc)))
    except BaseException as exc:
        results.put(("error", repr(exc)))


@pytest.fixture(scope="module")
def context():
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["mrpctl.campaign.run", "mrpctl.campaign.store", "test_campaign_integrity"])
    return ctx


#: Attempts of the two-writer race: 6 in the suite (about 1.4 s each), 40 in ``make catalogue`` (MRPCTL_STRESS=1).
WRITER_ATTEMPTS = 40 if os.environ.get("MRPCTL_STRESS") == "1" else 6


@pytest.mark.slow
def test_two_concurrent_writers_never_damage_the_store(clean, tmp_path, context):
    """Two processes started together on one new --out, WRITER_ATTEMPTS times; one proceeds (the other is refused,
    naming the holder) or they serialise (the second resumes a complete store); the store equals the clean one."""
    outcomes = []
    for attempt in range(WRITER_ATTEMPTS):
        out = str(tmp_path / f"out{attempt}")
        go, results = context.Event(), context.Queue()
        children = [context.Process(target=_writer, args=(out, go, results)) for _ in range(2)]
        for child in children:
            child.start()
        go.set()
        for child in children:
            child.join(120)
            assert child.exitcode == 0
        got = sorted(results.get(timeout=5) for _ in children)
        assert all(kind in ("ran", "locked") for kind, _ in got), got
        ran = [value for kind, value in got if kind == "ran"]
        assert len(ran) >= 1 and sum(ran) == 3, got  # the 3 chunks are simulated once in all
        for kind, value in got:
            if kind == "locked":
                assert "is being written by another process" in value and "pid" in value
        outcomes.append("refused" if len(ran) == 1 else "serialised")
        assert _tree(Path(out)) == _tree(clean)
    print("concurrent writers:", {k: outcomes.count(k) for k in set(outcomes)})


def test_a_held_lock_refuses_and_a_dead_holders_lock_is_taken_over(tmp_path, context):
    out = tmp_path / "out"
    ready, release = context.Event(), context.Event()
    holder = context.Process(target=_hold, args=(str(out), ready, release))
    holder.start()
    assert ready.wait(60)
    with pytest.raises(StoreLockedError, match=f"pid {holder.pid}"):
        run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=CHUNK, threads=1)
    assert not (out / STORE_NAME).exists()  # refused before the first byte of the store
    holder.kill()  # SIGKILL: no clean-up ran, the lock file still names the dead pid
    holder.join()
    assert json.loads((out / LOCK_NAME).read_text())["pid"] == holder.pid
    assert run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=CHUNK, threads=1).complete
    assert json.loads((out / LOCK_NAME).read_text())["pid"] == os.getpid()


def test_a_stale_lock_file_of_a_dead_pid_is_taken_over(tmp_path):
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_NAME).write_text(json.dumps({"host": os.uname().nodename, "pid": gone.pid, "started": "then"}))
    assert run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=CHUNK, threads=1).complete


def test_the_lock_is_released_on_exceptions_and_ctrl_c(tmp_path):
    out = tmp_path / "out"

    def stop(index, start, stop):
        raise KeyboardInterrupt

    for _ in range(2):
        with pytest.raises(KeyboardInterrupt):
            run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=CHUNK, threads=1, on_chunk=stop)
        fd = os.open(out / LOCK_NAME, os.O_RDWR)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # free: another open file description gets it
        finally:
            os.close(fd)
    started = time.monotonic()
    assert run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, threads=1).complete
    assert time.monotonic() - started < 120
