"""Tests of houghcad.engine on real local Dask clusters, with tiny stand-in tasks."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from houghcad.engine import Engine, Outcome, peak_rss_mb, report, reset_peak_rss


def square_or_trouble(item: tuple[str, int, str]) -> int:
    """``("ok", n, _)`` → n²; "flaky" raises OSError on its first attempt (marker file ``item[2]``);
    "bad" always raises; "hang" sleeps; "big" holds 200 MB for a moment."""
    kind, n, marker = item
    report("seen", n=n)
    if kind == "flaky" and not Path(marker).exists():
        Path(marker).write_text("first attempt")
        raise OSError("the shared disk hiccuped")
    if kind == "bad":
        raise ValueError(f"item {n} is bad")
    if kind == "hang":
        time.sleep(120)
    if kind == "big":
        block = bytearray(200 * 2**20)
        block[:: 4096] = b"x" * len(block[:: 4096])  # touch every page
    return n * n


def die(code: int) -> int:
    report("loaded", code=code)
    os._exit(code)


def test_outcomes_in_order_with_retries_timeouts_events_and_memory(tmp_path: Path):
    items = [("ok", 1, ""), ("flaky", 2, str(tmp_path / "flaky")), ("bad", 3, ""), ("hang", 4, ""),
             ("big", 5, ""), ("ok", 6, "")]
    events: list[tuple[int, str]] = []
    seen: list[int] = []
    t0 = time.monotonic()
    with Engine(workers=2, retries=1, timeout=4) as engine:
        assert engine.n_workers == 2 and engine.dashboard_link.startswith("http://127.0.0.1:")
        out = engine.run(square_or_trouble, items, on_event=lambda i, ev: events.append((i, ev["kind"])),
                         on_outcome=lambda o: seen.append(o.index))
    assert time.monotonic() - t0 < 60
    assert [o.index for o in out] == list(range(6)) and sorted(seen) == list(range(6))
    assert [o.status for o in out] == ["done", "done", "failed", "timeout", "done", "done"]
    assert [o.value for o in out if o.status == "done"] == [1, 4, 25, 36]
    assert out[1].attempts == 2  # the OSError was retried (Dask's retries=)
    assert out[2].error == "ValueError: item 3 is bad" and out[2].attempts == 2
    assert out[3].error == "timeout after 4 s"
    assert out[4].peak_mb > out[0].peak_mb + 150 and out[4].peak_scope == "task"
    assert (1, "start") in events and (1, "seen") in events and (3, "start") in events


def test_a_dead_worker_is_an_outcome_with_its_exit_code_and_the_run_goes_on():
    with Engine(workers=1, retries=0) as engine:
        died, done = engine.run(die, [7]), engine.run(abs, [-3])
    assert died == [Outcome(0, "died", error="worker died (exit code 7)", attempts=1, worker=died[0].worker)]
    assert done[0].status == "done" and done[0].value == 3


def test_bad_arguments_and_use_outside_a_cluster():
    with pytest.raises(ValueError):
        Engine(workers=0)
    with pytest.raises(ValueError):
        Engine(retries=-1)
    with pytest.raises(ValueError):
        Engine(object(), scheduler="tcp://127.0.0.1:1")
    with pytest.raises(RuntimeError):
        Engine().run(abs, [1])
    report("nothing")  # outside a worker: does nothing
    assert reset_peak_rss() in (True, False) and peak_rss_mb() > 10
