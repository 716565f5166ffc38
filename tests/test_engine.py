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


def die_at_once(code: int) -> int:
    """Ends its worker before the start event, batched, has left it."""
    os._exit(code)


def nap_or_die(item: tuple[str, float, str]) -> str:
    """``("nap", s, _)`` sleeps s seconds; ``("again", s, marker)`` returns at once the first
    time and sleeps s seconds when computed again; ``("die", _, marker)`` writes the marker and
    kills its worker."""
    kind, seconds, marker = item
    if kind == "again":
        if not Path(marker).exists():
            Path(marker).write_text("first")
            return "first"
        time.sleep(seconds)
        return "again"
    if kind == "die":
        report("dying")  # a round trip: the start event is delivered before the process ends
        Path(marker).write_text("died")
        os._exit(3)
    time.sleep(seconds)
    return kind


def slow_setup() -> None:
    time.sleep(1.5)


@pytest.fixture(scope="module")
def one_worker():
    """One single-threaded worker, no retries, tasks timed out after 1 s."""
    with Engine(workers=1, retries=0, timeout=1) as engine:
        yield engine


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


def test_a_timeout_costs_the_tasks_queued_behind_it_nothing(one_worker):
    # The timed-out task's worker got the next task as soon as the task was cancelled, then was
    # restarted: that innocent task counted a worker death and, with no retries, ended "died".
    t0 = time.monotonic()
    out = one_worker.run(nap_or_die, [("nap", 60, ""), ("nap", 0.1, ""), ("nap", 0.1, "")])
    assert [o.status for o in out] == ["timeout", "done", "done"], out
    assert out[0].error == "timeout after 1 s" and [o.attempts for o in out[1:]] == [1, 1]
    assert time.monotonic() - t0 < 20


def test_a_task_that_returns_past_its_time_is_a_timeout(one_worker):
    # The client's loop busy (here in on_outcome; it was in a worker's restart) while a task runs
    # past its time and returns: it came back "done", its time over the limit.
    out = one_worker.run(nap_or_die, [("nap", 0.0, ""), ("nap", 1.4, "")],
                         on_outcome=lambda o: time.sleep(2.5) if o.index == 0 else None)
    assert [o.status for o in out] == ["done", "timeout"], out
    assert out[1].seconds > 1.3 and out[1].value == "nap" and out[1].error.startswith("timeout after 1 s (it ran 1.")
    assert out[0].seconds < 1


def test_the_setup_of_a_worker_is_not_charged_to_the_task(one_worker):
    out = one_worker.run(abs, [-2], setup=slow_setup)
    assert out[0].status == "done" and out[0].value == 2 and out[0].seconds < 1


def test_a_result_lost_with_its_worker_is_computed_again(one_worker, tmp_path: Path):
    # "again" returns, then "die" kills their worker before the client took the result (it is
    # busy in on_outcome): Dask computes "again" anew. It came back "failed: NoneType: None"
    # (the exception of a future that has none).
    marker = tmp_path / "died"

    def wait_for_the_death(o: Outcome) -> None:
        if o.index == 0:
            while not marker.exists():
                time.sleep(0.02)
            time.sleep(0.3)

    out = one_worker.run(nap_or_die, [("nap", 0.0, ""), ("again", 0.5, str(tmp_path / "again")), ("die", 0, str(marker))],
                         on_outcome=wait_for_the_death)
    assert [o.status for o in out] == ["done", "done", "died"], out
    assert out[1].value == "again" and out[2].error == "worker died (exit code 3)"
    assert not any("NoneType" in (o.error or "") for o in out)


def test_an_erred_future_without_an_exception_says_so():
    class Erred:
        status = "error"

        def exception(self):
            return None

    from houghcad.engine import _Running

    outcome = Engine()._outcome(_Running(4, Erred(), attempts=1), Erred())
    assert outcome.status == "died" and outcome.error == "worker lost the task without an error"


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


def test_every_item_that_died_as_often_says_so_in_the_same_words():
    # One item lost its start events with its workers and read "worker died (exit code 5)",
    # the other "worker died 2 times (exit code 5)": the count is the scheduler's now.
    with Engine(workers=2, retries=1) as engine:
        out = engine.run(die_at_once, [5, 5])
    assert [(o.status, o.error, o.attempts) for o in out] == [("died", "worker died 2 times (exit code 5)", 2)] * 2


def test_a_killed_workers_deaths_and_pid_come_from_the_scheduler():
    from types import SimpleNamespace

    from distributed.scheduler import KilledWorker

    from houghcad.enginedask import death_message, killed_worker

    assert killed_worker(KilledWorker("k", SimpleNamespace(pid=4321), 2)) == (3, 4321)
    assert killed_worker(ValueError("not Dask's")) == (None, None)
    assert death_message(1, 7) == "worker died (exit code 7)"
    assert death_message(3, -9) == "worker died 3 times (exit code -9) (SIGKILL: out of memory?)"
    assert death_message(2, None) == "worker died 2 times"


class _Link:
    """A client as far as the dashboard link goes."""

    def __init__(self, link: str | None = None, error: type[Exception] | None = None) -> None:
        self.link, self.error = link, error

    @property
    def dashboard_link(self) -> str | None:
        if self.error is not None:
            raise self.error("services")
        return self.link


def test_the_dashboard_link_is_given_only_when_the_scheduler_serves_the_page():
    import http.server
    import threading

    class Server(http.server.BaseHTTPRequestHandler):
        # As a scheduler's HTTP server: started with --no-dashboard it has no /status (404); the
        # dashboard's handler, or the page asking for bokeh, takes GET only (HEAD: 405).
        def do_HEAD(self) -> None:
            self.send_response(405 if self.path == "/status" else 404)
            self.end_headers()

        def log_message(self, *args) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Server)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        assert Engine(_Link(f"{base}/status")).dashboard_link == f"{base}/status"
        assert Engine(_Link(f"{base}/gone")).dashboard_link is None
    finally:
        server.shutdown()
        server.server_close()
    assert Engine(_Link(f"{base}/status")).dashboard_link is None  # nothing listens there now
    assert Engine(_Link("")).dashboard_link is None and Engine(_Link(error=KeyError)).dashboard_link is None
    assert Engine().dashboard_link is None  # outside its 'with' block


def test_a_taken_dashboard_port_is_no_warning_and_the_link_gives_the_port_used():
    import socket
    import warnings

    holder = socket.socket()
    try:
        holder.bind(("127.0.0.1", 8787))  # else something holds it already: the same case
        holder.listen()
    except OSError:
        pass
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with Engine(workers=1) as engine:
                link = engine.dashboard_link
    finally:
        holder.close()
    assert not [w for w in caught if "already in use" in str(w.message)]
    assert link.startswith("http://127.0.0.1:") and ":8787/" not in link
