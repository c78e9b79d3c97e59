"""Distributed bake on dask.distributed (docs/DISTRIBUTED.md): --workers 2 and an existing scheduler give the store an
in-process bake gives, byte for byte, also when a worker or the client is killed with SIGKILL on the way."""

import glob
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lodprt.errors import LodprtError
from lodprt.store.sample_groups import complete_samples

from test_resume import FAST, api_bake, assert_same_store, kill_at, lodprt, scene_file

distributed = pytest.importorskip("distributed", reason="the distributed extra (pip install 'lodprt[distributed]')")


def descendants(pid):
    """Processes started by ``pid`` (from any of its threads) and theirs."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        for f in glob.glob(f"/proc/{p}/task/*/children"):
            try:
                kids = [int(k) for k in Path(f).read_text().split()]
            except OSError:
                continue
            out += kids
            todo += kids
    return out


def running(pid):
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_missing_extra_names_the_install_command(tmp_path, monkeypatch):
    """Without dask.distributed, --workers fails before any work with the pip command of the extra."""
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed now raises ImportError
    toml = scene_file(tmp_path, grid=(1, 1, 1))
    with pytest.raises(LodprtError, match=r"pip install 'lodprt\[distributed\]'"):
        api_bake(toml, tmp_path / "out.zarr", workers=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]


def test_workers_2_with_a_worker_killed_is_byte_identical(tmp_path):
    """lodprt bake --workers 2, one worker process killed with SIGKILL after a few samples: the bake finishes
    (the scheduler runs the lost task again) and equals the in-process bake; -v prints the dashboard link."""
    toml = scene_file(tmp_path)
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref)
    out = tmp_path / "out.zarr"
    proc = subprocess.Popen(lodprt("-v", "bake", toml, "-o", out, *FAST, "--workers", "2"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + 120
        partial = out.with_name(f"out.zarr.partial-{proc.pid}")
        while proc.poll() is None and time.monotonic() < end and len(complete_samples(partial, 16)) < 3:
            time.sleep(0.005)
        workers = [p for p in descendants(proc.pid) if "spawn_main" in Path(f"/proc/{p}/cmdline").read_text()]
        assert proc.poll() is None and len(workers) == 2, "the bake finished before a worker could be killed"
        os.kill(workers[0], signal.SIGKILL)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 0, err
    assert "dask dashboard: http" in err and "Traceback" not in err
    assert_same_store(ref, out)


def test_client_killed_then_resumed_in_process(tmp_path):
    """SIGKILL of the client of a --workers 2 bake: its workers stop, the samples they finished stay in the partial
    folder, and --resume (in-process here) completes a store equal to an uninterrupted bake."""
    toml = scene_file(tmp_path)
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref)
    out = tmp_path / "out.zarr"
    cmd = lodprt("bake", toml, "-o", out, *FAST)
    seen = []

    def some_samples(folder):
        seen[:] = descendants(int(folder.name.rsplit("-", 1)[1]))
        return len(complete_samples(folder, 16)) >= 3

    partial = kill_at(cmd + ["--workers", "2"], tmp_path / "out.zarr.partial-*", some_samples, deadline=120)
    end = time.monotonic() + 30
    while any(running(p) for p in seen) and time.monotonic() < end:
        time.sleep(0.2)
    assert seen and not any(running(p) for p in seen), "worker processes outlived their client"
    kept = complete_samples(partial, 16)
    r = subprocess.run(cmd + ["--jobs", "1", "--resume"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert f"{len(kept)} of 16 light samples were already in the store" in r.stderr
    assert_same_store(ref, out)


def test_existing_scheduler_keeps_one_device_state_per_worker(tmp_path):
    """scheduler=ADDRESS bakes on a running cluster (here two thread workers): the same store as in-process, and the
    workers hold the job's device state (made at their first task) afterwards, not one per task."""
    from lodprt.precompute import bake as bake_module

    toml = scene_file(tmp_path, grid=(3, 1, 2))
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref)
    out = tmp_path / "out.zarr"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        made = []
        original = bake_module.SampleJob.device_state

        def counting(job):
            made.append(job.token)
            return original(job)

        bake_module.SampleJob.device_state = counting
        try:
            res = api_bake(toml, out, scheduler=cluster.scheduler_address)
        finally:
            bake_module.SampleJob.device_state = original
    assert_same_store(ref, out)
    assert len(made) == 1 and res.reused_samples == 0  # thread workers share this process: one state, 6 tasks
    with pytest.raises(LodprtError, match="give either --workers N"):
        api_bake(toml, tmp_path / "x.zarr", workers=2, scheduler="tcp://127.0.0.1:1")


def test_interreflection_on_a_cluster_and_resumed(tmp_path):
    """bounces > 0 with scheduler= (two thread workers) and with a resumed bake: each sample's group records its
    pass energies, so both give the in-process store byte for byte (root bounce_energy included)."""
    import zarr

    toml = scene_file(tmp_path, grid=(4, 1, 1))
    gi = {"bounces": 1, "gi_rays": 8}
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref, **gi)
    out = tmp_path / "out.zarr"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        api_bake(toml, out, scheduler=cluster.scheduler_address, **gi)
    assert_same_store(ref, out)
    energy = zarr.open_group(str(out), mode="r").attrs["bounce_energy"]
    assert len(energy) == 4 and all(len(e) == 2 and e[1] > 0 for e in energy)
    resumed = tmp_path / "resumed.zarr"  # a CLI bake killed with SIGKILL after its first samples, then resumed
    cmd = lodprt("bake", toml, "-o", resumed, *FAST, "--bounces", "1", "--gi-rays", "8", "--jobs", "1")
    kill_at(cmd, tmp_path / "resumed.zarr.partial-*", lambda folder: len(complete_samples(folder, 4)) >= 1)
    res = api_bake(toml, resumed, resume=True, **gi)
    assert 1 <= res.reused_samples < 4
    assert_same_store(ref, resumed)
