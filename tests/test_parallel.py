"""Tests of houghcad.parallel: workers forked once per run give what this process computes, in
job order; without fork (or with one job) there are no workers."""

from __future__ import annotations

import copy
import signal
import sys
import time
import multiprocessing as mp
from dataclasses import replace

import numpy as np
import pytest

from houghcad import families, parallel, synth
from houghcad.context import derive_context
from houghcad.noise import CLEAN, NOISY
from houghcad.parallel import Workers, available_cores, can_fork, resolve_jobs
from houghcad.preprocess import preprocess
from houghcad.consolidation import revisit_poor_fits
from houghcad.recognize import candidates, recognize
from houghcad.splitting import ransac_recognised, recognise_cluster
from houghcad.state import Segmentation
from houghcad.tolerances import Tolerances

needs_fork = pytest.mark.skipif(not can_fork(), reason="no fork start method here")


@pytest.fixture(scope="module")
def run():
    cloud = synth.block_with_hole_and_slot(seed=3, n_points=4000)
    pre = preprocess(cloud.points)
    ctx = derive_context(pre, len(cloud.points), Tolerances(), CLEAN)
    return ctx, families.select("simple")


def _same(a, b) -> None:
    """Two lists of candidates are equal: families (the same objects), primitives, points."""
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.family is y.family
        assert repr(x.prim) == repr(y.prim)
        np.testing.assert_array_equal(x.indices, y.indices)
        assert x.mfe == y.mfe


@needs_fork
def test_workers_compute_what_this_process_computes(run):
    ctx, fams = run
    n = len(ctx.pre.points)
    avail = np.ones(n, bool)
    halves = [np.arange(0, n // 2), np.arange(n // 2, n)]
    lctx = replace(ctx, local=True, min_points=ctx.min_points + 5)  # scalar changes travel to the workers
    with Workers(ctx, fams, 2) as w:
        assert w.pool is not None
        got = w.run("recognize", [(h, fams, None) for h in halves], lctx)
        clusters = w.run("cluster", [(h, fams, None) for h in halves], lctx)
        spread = w.candidates(halves[0], fams, lctx)
    assert got is not None and clusters is not None and spread is not None
    for h, g, c in zip(halves, got, clusters):
        _same(g, recognize(h, fams, lctx, avail))
        want = recognise_cluster(h, fams, lctx, avail)
        _same(c[0], want[0])
        assert (c[1] is None) == (want[1] is None)
    _same(spread, candidates(halves[0], fams, lctx, avail))
    assert w.pool is None  # closed


def _records(seg: Segmentation, items: list[int], ctx, fams, extra: int) -> list:
    """What a task over a segmentation reads back: each item's segment, its size and record."""
    return [(k, len(seg.indices(k)), seg.records[k], [f.name for f in fams], extra) for k in items]


@needs_fork
def test_tasks_over_a_segmentation_and_submitted_tasks(run):
    ctx, fams = run
    n = len(ctx.pre.points)
    avail = np.ones(n, bool)
    seg = Segmentation.of(n, recognize(np.arange(n), fams, ctx, avail))
    items = list(range(len(seg)))[::-1]
    assert len(items) >= 4
    with Workers(ctx, fams, 2) as w:
        got = w.map_segments(_records, seg, items, ctx, fams[:2], 7)
        assert w.map_segments(_records, seg, items[:3], ctx, fams, 7) is None  # fewer than 2 per worker
        assert w.map_segments(_records, seg, items, ctx, [copy.copy(fams[0])], 7) is None  # foreign family
        wait = w.submit("recognize", [(np.arange(n // 2), fams, None)], ctx)  # even one job
        assert wait is not None
        later = wait()
    want = _records(seg, items, ctx, fams[:2], 7)
    assert [(k, m, f, e) for k, m, _, f, e in got] == [(k, m, f, e) for k, m, _, f, e in want]  # in item order
    for (*_, a, _f, _e), (*_, b, _g, _h) in zip(got, want):
        assert a.family is b.family and repr(a.prim) == repr(b.prim)  # families come back as the run's
    _same(later[0], recognize(np.arange(n // 2), fams, ctx, avail))


@needs_fork
def test_ransac_regions_and_poor_fits_on_workers(run, monkeypatch):
    """The splitting phase's RANSAC regions and consolidation's votes on poorly fitted segments
    give on the workers what they give here."""
    ctx, fams = run
    n = len(ctx.pre.points)
    avail = np.ones(n, bool)
    want = ransac_recognised(np.arange(n), fams, ctx, avail)
    # Planes alone on a noisy part: poor fits across its cones for consolidation to revisit.
    pre = preprocess(synth.mirrored_cones(seed=3, n_points=4000, noise=0.002).points)
    m = len(pre.points)
    nctx = derive_context(pre, m, Tolerances(), NOISY)
    seg = Segmentation.of(m, recognize(np.arange(m), fams[:1], nctx, np.ones(m, bool)))
    here, there = seg.copy(), seg.copy()
    assert revisit_poor_fits(here, fams, nctx)
    handed_out = []
    run_jobs = Workers.run

    def spy(self, what, jobs, c):
        got = run_jobs(self, what, jobs, c)
        handed_out.append((what, got is not None))
        return got

    monkeypatch.setattr(Workers, "run", spy)
    with Workers(ctx, fams, 2) as w:
        _same(ransac_recognised(np.arange(n), fams, replace(ctx, workers=w), avail), want)
    with Workers(nctx, fams, 2) as w:
        assert revisit_poor_fits(there, fams, replace(nctx, workers=w))
    assert ("recognize", True) in handed_out and ("candidates", True) in handed_out
    np.testing.assert_array_equal(here.labels, there.labels)
    assert [repr(r) for r in here.records] == [repr(r) for r in there.records]


@needs_fork
def test_workers_decline_what_they_cannot_rebuild(run):
    ctx, fams = run
    jobs = [(np.arange(0, 1500), fams, None), (np.arange(1500, 3000), fams, None)]
    with Workers(ctx, fams, 2) as w:
        assert w.run("recognize", jobs, replace(ctx, neighbors=np.zeros((3, 2), int))) is None  # an array
        assert w.run("recognize", jobs, replace(ctx, tol=Tolerances())) is None  # another object
        other = families.select("plane")[0]
        assert w.run("recognize", [(np.arange(1500), [copy.copy(other)], None), jobs[1]], ctx) is None  # foreign
        assert w.run("recognize", jobs[:1], ctx) is None  # one job: not worth it
        small = [(np.arange(10), fams, None), (np.arange(10, 20), fams, None)]
        assert w.run("recognize", small, ctx) is None  # under PARALLEL_MIN_POINTS in all
        assert w.candidates(np.arange(30), fams, replace(ctx, tol=Tolerances())) is None
        assert w.run("recognize", jobs, ctx) is not None


def test_one_job_or_no_fork_means_no_workers(run, monkeypatch):
    ctx, fams = run
    with Workers(ctx, fams, 1) as w:
        assert w.pool is None and w.run("recognize", [(np.arange(2000), fams, None)] * 2, ctx) is None
        assert w.candidates(np.arange(2000), fams, ctx) is None
    monkeypatch.setattr(mp.current_process(), "_config", {**mp.current_process()._config, "daemon": True})
    assert not can_fork()
    with Workers(ctx, fams, 2) as w:
        assert w.pool is None
    assert parallel._BASE is None


def test_resolve_jobs():
    assert resolve_jobs(None) == resolve_jobs(0) == available_cores() >= 1
    assert resolve_jobs(3) == 3
    assert resolve_jobs(-1) == available_cores()
    assert resolve_jobs(-1000) == 1
    assert resolve_jobs(1000) == 4 * available_cores()  # not a thousand processes


@needs_fork
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_leave_ctrl_c_to_the_main_process(run):
    """Ctrl-C reaches the whole process group: workers that died of it printed their own
    'Process ForkPoolWorker-N:' lines after the CLI's one-line message."""
    ctx, fams = run
    def ignores_sigint(pid: int) -> bool:
        status = open(f"/proc/{pid}/status").read()
        ignored = int(next(line for line in status.splitlines() if line.startswith("SigIgn:")).split()[1], 16)
        return bool(ignored & (1 << (signal.SIGINT - 1)))

    with Workers(ctx, fams, 2) as w:
        pids = [p.pid for p in w.pool._pool]
        # The pool returns before its workers have run their initializer: give them time to start.
        deadline = time.monotonic() + 20.0
        while not all(map(ignores_sigint, pids)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert all(map(ignores_sigint, pids))


def test_a_run_uses_one_blas_thread_and_gives_the_callers_back():
    """BLAS's threads only hand our small products around and spin between calls, taking the
    other core: a run limits them to one, and the caller's setting comes back after."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import houghcad
    from houghcad import synth

    def blas_threads() -> list[int]:
        return [d["num_threads"] for d in threadpoolctl.threadpool_info() if d["user_api"] == "blas"]

    seen: list[list[int]] = []
    P = synth.block_with_hole_and_slot(seed=0, n_points=1500).points
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        houghcad.segment(P, families="plane", n_jobs=1, trace=lambda step, name, seg: seen.append(blas_threads()))
        assert blas_threads() == before
    assert seen and all(n == 1 for threads in seen for n in threads)


def _die_by_signal() -> None:
    import os

    os.kill(os.getpid(), signal.SIGKILL)


@needs_fork
def test_a_worker_that_dies_stops_the_wait_instead_of_hanging(run):
    # A crash in native code (CGAL on a degenerate cluster) killed a worker: the Pool started
    # another in its place and the run waited for the lost task forever.
    ctx, fams = run
    with Workers(ctx, fams, 2) as w:
        t = time.perf_counter()
        with pytest.raises(parallel.WorkerDied, match="SIGKILL"):
            w._get(w.pool.apply_async(_die_by_signal))
        assert time.perf_counter() - t < 10
