"""Interrupted bakes: what a killed writer leaves behind never confuses the next one (docs/FORMAT.md)."""

import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lodprt.errors import StoreError
from lodprt.store.bake_store import FORMAT_VERSION, open_store
from lodprt.store.sample_groups import complete_samples, is_complete
from lodprt.store.writer import FORMAT_NAME, OWNER_FILE, StoreWriter, clean_leftovers, process_identity, writer_alive

from conftest import BUNNY, SPOT


def sleeper():
    """A live process that is not this one (killed by the caller)."""
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])


def dead_identity():
    """The owner record of a process that ran and has exited (start time taken while it lived)."""
    p = sleeper()
    ident = process_identity(p.pid)
    p.kill()
    p.wait()
    return ident


def write_store(path, value=1.0, *, overwrite=False):
    """A tiny committed lodprt store (no kernels needed): what the writer makes, whatever the bake computes."""
    w = StoreWriter(path, overwrite=overwrite)
    w.array("scene/positions", np.full((4, 3), value, np.float32))
    w.attrs(format=FORMAT_NAME, format_version=FORMAT_VERSION)
    return w.commit()


def leftover(dest, owner, kind="partial", *, record=True, value=2.0):
    """A ``<dest>.<kind>-<pid>`` folder as a writer with ``owner`` leaves it when killed (format attribute set)."""
    tmp = dest.with_name("scratch.zarr")
    w = StoreWriter(tmp, overwrite=False)
    w.array("scene/positions", np.full((4, 3), value, np.float32))
    w.attrs(format=FORMAT_NAME, format_version=FORMAT_VERSION)
    folder = dest.with_name(f"{dest.name}.{kind}-{owner['pid']}")
    w.partial.rename(folder)
    if record:
        (folder / OWNER_FILE).write_text(json.dumps(owner))
    else:
        (folder / OWNER_FILE).unlink()
    return folder


def snapshot(folder):
    """Every file under ``folder`` with its bytes (byte-identical comparison)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(Path(folder).rglob("*")) if p.is_file()}


def test_dead_partial_removed_live_partial_kept(tmp_path, caplog):
    """The next writer removes the partial folder of a dead bake and leaves that of a running process alone."""
    dest = tmp_path / "b.zarr"
    dead = leftover(dest, dead_identity())
    live_proc = sleeper()
    try:
        live = leftover(dest, process_identity(live_proc.pid))
        with caplog.at_level(logging.INFO, logger="lodprt.store"):
            write_store(dest)
        assert not dead.exists() and live.is_dir() and (live / OWNER_FILE).is_file()
        assert open_store(dest).positions.shape == (4, 3)
        assert f"{dead}: removed" in caplog.text and "still running" in caplog.text
    finally:
        live_proc.kill()
        live_proc.wait()
    gone = f"{live}: removed, left by an interrupted bake (pid {live_proc.pid}, no longer running)"
    assert clean_leftovers(dest) == [gone]  # once its writer has died, the next writer may tidy it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.zarr"]


def test_pid_reuse_other_hosts_and_foreign_folders(tmp_path, caplog):
    """Reused pids count as dead, record-less/empty dead partials go, other hosts' and foreign folders stay."""
    me = process_identity()
    if me["start"] is not None:  # /proc gives start times: a record with another start is a reused pid
        assert writer_alive(dict(me, start=me["start"] - 1)) is False
    assert writer_alive(me) is True
    dest = tmp_path / "b.zarr"
    gone = dead_identity()
    remote = leftover(dest, dict(gone, host="some-other-host"))
    legacy = leftover(dest, dict(gone, pid=gone["pid"] + 1_000_000), record=False)  # no record: the name's pid
    mine = dest.with_name(f"{dest.name}.partial-{gone['pid'] + 2_000_000}")
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    empty = dest.with_name(f"{dest.name}.partial-{gone['pid'] + 3_000_000}")  # killed before its owner record
    empty.mkdir()
    with caplog.at_level(logging.INFO, logger="lodprt.store"):
        actions = clean_leftovers(dest)
    removed = ((legacy, gone["pid"] + 1_000_000), (empty, gone["pid"] + 3_000_000))
    assert sorted(actions) == sorted(f"{f}: removed, left by an interrupted bake (pid {pid}, no longer running)"
                                     for f, pid in removed)
    assert remote.is_dir() and (mine / "thesis.tex").read_text() == "precious"
    assert "some-other-host" in caplog.text and f"{mine}: named like a leftover" in caplog.text


def test_killed_inside_commit_restores_previous_store(tmp_path):
    """Killed between parking the old store and moving the new one in: the old store comes back, byte for byte."""
    dest = write_store(tmp_path / "b.zarr")
    before = snapshot(dest)
    owner = dead_identity()
    # the state a SIGKILL between commit()'s two renames leaves: old store parked, finished new store beside it
    parked = dest.with_name(f"{dest.name}.replaced-{owner['pid']}")
    dest.rename(parked)
    (parked / OWNER_FILE).write_text(json.dumps(owner))
    new = leftover(dest, owner, record=False, value=3.0)
    with pytest.raises(StoreError, match="already exists"):  # restored, so a bake without overwrite refuses
        StoreWriter(dest, overwrite=False)
    assert snapshot(dest) == before and not parked.exists() and not new.exists()
    # killed after the new store moved in: the parked old one is deleted, the new one stays
    owner = dead_identity()
    parked = dest.with_name(f"{dest.name}.replaced-{owner['pid']}")
    parked.mkdir()
    (parked / OWNER_FILE).write_text(json.dumps(owner))
    (parked / "zarr.json").write_text((dest / "zarr.json").read_text())
    write_store(dest, 4.0, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.zarr"]
    assert (open_store(dest).positions == 4.0).all() and not (dest / OWNER_FILE).exists()


def lodprt(*args):
    return [sys.executable, "-m", "lodprt.cli.main", *map(str, args)]


def test_sigkill_mid_bake_leaves_destination_untouched(tmp_path):
    """SIGKILL mid-bake keeps the old store byte-identical; the next bake succeeds and removes the dead partial."""
    small = tmp_path / "small.toml"
    small.write_text(f'[[object]]\nmesh = "{SPOT.as_posix()}"\n[floor]\nresolution = 10\n[lights]\ngrid = [1, 1, 1]\n')
    big = tmp_path / "big.toml"  # the hierarchy of the bunny on a floor takes seconds: time to kill it
    bunny = BUNNY.as_posix()
    big.write_text(f'[[object]]\nmesh = "{bunny}"\n[floor]\nresolution = 60\n[lights]\ngrid = [2, 1, 2]\n')
    out = tmp_path / "out.zarr"
    fast = ["--device", "cpu", "--sh-order", "2", "--full", "--no-hierarchy"]
    r = subprocess.run(lodprt("bake", small, "-o", out, *fast), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    before = snapshot(out)
    proc = subprocess.Popen(lodprt("bake", big, "-o", out, "--device", "cpu", "--overwrite"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 20
        while not list(tmp_path.glob("out.zarr.partial-*")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        partial = out.with_name(f"out.zarr.partial-{proc.pid}")
        assert partial.is_dir(), "the bake never made its partial folder (or finished first)"
        while not (partial / "scene").is_dir() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)  # kernels loaded, scene arrays being written; the hierarchy build comes next
        assert proc.poll() is None, "the bake finished before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert snapshot(out) == before
    assert partial.is_dir()  # what SIGKILL leaves: nothing could clean up
    r = subprocess.run(lodprt("bake", small, "-o", out, *fast, "--overwrite"), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert f"{partial}: removed" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.toml", "out.zarr", "small.toml"]
    assert open_store(out).num_samples == 1


def test_sigint_mid_bake_exits_130_keeps_partial_and_resume_finishes(tmp_path):
    """Ctrl-C while the light samples bake: exit status 130, one line (no traceback) naming the partial folder and
    --resume; the folder holds the finished samples, and bake --resume reuses them and completes the store."""
    scene = tmp_path / "big.toml"  # 36 samples of the bunny on a floor at ~0.05 s each: seconds to interrupt in
    scene.write_text(f'[[object]]\nmesh = "{BUNNY.as_posix()}"\n[floor]\nresolution = 60\n[lights]\ngrid = [6, 1, 6]\n')
    out = tmp_path / "out.zarr"
    args = ["bake", scene, "-o", out, "--device", "cpu", "--sh-order", "3", "--full", "--no-hierarchy", "--jobs", "1"]
    proc = subprocess.Popen(lodprt(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    partial = out.with_name(f"out.zarr.partial-{proc.pid}")
    try:
        deadline = time.monotonic() + 120
        while not is_complete(partial / "samples" / "00000") and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert proc.poll() is None, "the bake finished (or failed) before it could be interrupted"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    said = [line for line in err.splitlines() if "interrupted" in line]
    assert len(said) == 1 and partial.name in said[0] and "--resume" in said[0], err
    assert partial.is_dir() and not out.exists()
    done = len(complete_samples(partial, 36))
    assert 1 <= done < 36 and f"{done} finished light sample(s)" in said[0]
    r = subprocess.run(lodprt(*args, "--resume"), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"{done} of 36 light samples were already in the store" in r.stderr
    store = open_store(out)
    assert store.num_samples == 36 and complete_samples(out, 36) == list(range(36))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.toml", "out.zarr"]  # the partial became the store
    ids, coeffs = store.sample(35)  # --full: every referenced vertex
    assert len(ids) == int(store.referenced.sum()) and np.isfinite(coeffs).all()


def test_ctrl_c_inside_a_progress_bar_waits_until_the_bar_is_whole(monkeypatch):
    """A SIGINT that lands while tqdm builds a bar is raised once the bar exists (a half-made bar's finaliser
    printed a traceback at exit, so an interrupted bake printed more than its one line)."""
    import tqdm as tqdm_module

    from lodprt.cli.progress import new_bar

    made = []

    class Interrupted(tqdm_module.tqdm):
        def __init__(self, *args, **kwargs):
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C arrives while the bar is being made
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(tqdm_module, "tqdm", Interrupted)
    with pytest.raises(KeyboardInterrupt):
        new_bar(total=3, desc="bake", unit="sample")
    assert len(made) == 1 and hasattr(made[0], "pos")  # whole when the interrupt was raised
    made[0].close()
