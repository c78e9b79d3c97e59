"""``lodprt.launches.run_jobs``: the job pool of the sequential hierarchy build (tiles, then each component's rest).
Every job runs once, never before the jobs it waits for, on up to ``workers`` threads; the order of the ready jobs
follows the estimates; errors and cycles are raised in the calling thread."""

import threading
import time

import pytest

from lodprt.launches import Job, run_jobs


def chain_jobs(log, lock, sleep=0.0):
    """Two kinds of tiles, each kind's rest waiting for its own tiles (the build's shape)."""
    def rec(name):
        def run(cache):
            with lock:
                log.append(("start", name, threading.get_ident()))
            time.sleep(sleep)
            with lock:
                log.append(("end", name, threading.get_ident()))
        return run

    jobs = [Job(rec(f"a{k}"), size=10, kind="a", follow=5) for k in range(4)]
    jobs += [Job(rec(f"b{k}"), size=8, kind="b", follow=1) for k in range(2)]
    jobs += [Job(rec("a-rest"), size=5, kind="a", waits=4), Job(rec("b-rest"), size=1, kind="b", waits=2)]
    for k in range(4):
        jobs[k].then.append(6)
    for k in (4, 5):
        jobs[k].then.append(7)
    return jobs


@pytest.mark.parametrize("workers", [1, 2, 4])
def test_every_job_runs_once_after_what_it_waits_for(workers):
    log, lock, afters = [], threading.Lock(), []
    me = threading.get_ident()
    run_jobs(chain_jobs(log, lock, 0.002), workers, lambda: afters.append(threading.get_ident()))
    starts = [e[1] for e in log if e[0] == "start"]
    ends = {e[1]: i for i, e in enumerate(log) if e[0] == "end"}
    assert sorted(starts) == sorted(["a0", "a1", "a2", "a3", "b0", "b1", "a-rest", "b-rest"])
    start_at = {e[1]: i for i, e in enumerate(log) if e[0] == "start"}
    assert all(ends[f"a{k}"] < start_at["a-rest"] for k in range(4))
    assert all(ends[f"b{k}"] < start_at["b-rest"] for k in range(2))
    assert len({e[2] for e in log}) <= workers
    assert afters and set(afters) == {me}  # after() only in the calling thread, and once at the end


def test_one_thread_probes_each_kind_then_follows_the_estimates():
    """On one thread the order is the schedule itself: the largest job of each kind of several jobs first (a0, then
    b0, whose rate is then measured), then the longest estimates; a rest as soon as it is ready and longest."""
    log, lock = [], threading.Lock()
    run_jobs(chain_jobs(log, lock), 1)
    order = [e[1] for e in log if e[0] == "start"]
    assert order[:2] == ["a0", "b0"]
    assert order.index("a-rest") > order.index("a3") and order.index("b-rest") > order.index("b1")


def test_a_kind_named_none_of_several_jobs_is_probed_like_any_other():
    """``kind=None`` is a kind like any other (the default): its jobs share a measured rate and its largest is
    probed before the rest are placed, beside the one-job kinds; here the probe of None (n0) comes before the one-job
    kind's larger job (s)."""
    log = []

    def rec(name):
        return lambda cache: log.append(name)

    jobs = [Job(rec("s"), size=100, kind="single")] + [Job(rec(f"n{k}"), size=10 - k) for k in range(3)]
    run_jobs(jobs, 1)
    assert log[0] == "n0" and sorted(log) == ["n0", "n1", "n2", "s"]


def test_an_error_stops_the_pool_and_is_raised_here():
    ran = []

    def boom(cache):
        raise ValueError("job failed")

    jobs = [Job(boom, size=10), Job(lambda c: ran.append(1), size=1, waits=1)]
    jobs[0].then.append(1)
    with pytest.raises(ValueError, match="job failed"):
        run_jobs(jobs, 2)
    assert not ran


def test_jobs_that_wait_for_each_other_are_refused_not_hung():
    jobs = [Job(lambda c: None, size=1, waits=1, then=[1]), Job(lambda c: None, size=1, waits=1, then=[0])]
    with pytest.raises(RuntimeError, match="wait for each other"):
        run_jobs(jobs, 2)


def test_no_jobs_is_no_work():
    calls = []
    run_jobs([], 3, lambda: calls.append(1))
    assert calls == [1]


def test_the_caller_reports_another_threads_finished_job_while_it_waits():
    """A progress bar moves while the calling thread waits: the first two jobs meet at a barrier (so each thread
    runs one), the third waits for both. The caller's returns at once, the other thread's 0.2 s later; the caller,
    with nothing ready meanwhile, reports that job (2 done) before the third runs (it used to report only after
    its own next job, or at the end)."""
    done, reports, lock = [], [], threading.Lock()
    meet = threading.Barrier(2)
    main = threading.main_thread()

    def job(cache):
        if len(cache) == 0 and len(done) < 2:
            cache["met"] = True
            meet.wait(timeout=10)
        if threading.current_thread() is not main:
            time.sleep(0.2)
        with lock:
            done.append(threading.current_thread() is main)

    jobs = [Job(job, size=1, then=[2]), Job(job, size=1, then=[2]), Job(job, size=1, waits=2)]
    run_jobs(jobs, 2, lambda: reports.append(len(done)))
    assert sorted(done[:2]) == [False, True] and len(done) == 3
    assert reports[0] == 1  # after the caller's own job
    assert 2 in reports and reports[-1] == 3  # the other thread's job, while the caller waited; then the end
