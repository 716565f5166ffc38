"""One function over many items on a Dask cluster: the engine of ``houghcad batch``.

:class:`Engine` starts a local ``dask.distributed`` cluster (one single-threaded worker process
per core) or connects to a running scheduler, submits one task per item and collects how each
ended as an :class:`Outcome`, in the items' order whatever the completion order. Dask does the
scheduling; this module adds what a batch of long, independent tasks needs on top of it:

- tasks that raise are retried (``retries=`` of ``Client.submit``); a worker that dies mid-task
  has its task rescheduled on another worker by the scheduler (``allowed-failures``, set to
  ``retries`` on the clusters the engine starts), and past that the item ends ``died``;
- a task may run ``timeout`` seconds, measured from the moment it starts on its worker (time
  queued for a worker does not count, nor does the ``setup`` that loads the libraries of a fresh
  worker). The client checks every ``POLL`` seconds, from the task's start event: a task still
  running past its time ends ``timeout``, is cancelled and its worker process killed and replaced
  by its nanny (a thread cannot be stopped), about 0.05 s after its time on a local cluster. A
  task that returns having run longer (in that gap) ends ``timeout`` as well: ``done`` always
  means "within the limit". The stopping runs beside the loop, so that the other tasks' clocks
  are still watched meanwhile, and no task is handed to the worker being stopped;
- a task whose result was lost with its worker before the client took it (a worker restarted or
  dead) is computed again by Dask; the engine waits for it rather than reporting the loss;
- tasks tell the client when they start and, through :func:`report`, anything else (Dask's
  structured events), so a progress display knows what is running;
- the peak resident memory of each task (its worker's, reset when the task starts).

Determinism: each task is a pure function of its item; which worker runs it, and how many
workers there are, changes nothing in its value.
"""

from __future__ import annotations

import contextlib
import functools
import os
import queue
import re
import resource
import signal
import threading
import time
import uuid
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from .enginedask import ExitCodes, dask_logs_routed, death_message, killed_worker, served_dashboard

__all__ = ["Engine", "Outcome", "report", "peak_rss_mb", "reset_peak_rss"]

#: Dask event topic of the engine's messages (task start, and what tasks report).
TOPIC = "houghcad-engine"
#: Seconds between two looks at the futures and events when nothing happened.
POLL = 0.05
#: Seconds to wait for a worker's exit code after its task was declared dead.
EXIT_CODE_WAIT = 2.0
#: Seconds to wait, at the end of a run, for the stopping of workers whose task ran past its time.
STOP_WAIT = 30.0
#: States of a client future that has ended for good (a "lost" future is computed again).
_ENDED = ("finished", "error", "cancelled")


class _InterruptFlag:
    """Ctrl-C during :meth:`Engine.run`, kept until the loop sees it.

    The KeyboardInterrupt of SIGINT is raised wherever the main thread is; inside the Dask
    client's calls it can be lost (seen in CI: an interrupted batch ran to its end and exited 1
    about one run in four). The handler also sets a flag that the loop checks at every turn and
    once more at the end, so an interruption always ends the run as one.
    """

    def __init__(self) -> None:
        self.set = False
        self._previous = None
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.getsignal(signal.SIGINT)
            signal.signal(signal.SIGINT, self._handler)

    def _handler(self, signum: int, frame: Any) -> None:
        self.set = True
        raise KeyboardInterrupt

    def check(self) -> None:
        if self.set:
            raise KeyboardInterrupt

    def restore(self) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None


@dataclass
class Outcome:
    """How one item ended.

    Attributes
    ----------
    index : int
        Position of the item in the sequence given to :meth:`Engine.run`.
    status : str
        ``"done"`` (``value`` holds the return value), ``"failed"`` (the task raised on every
        attempt), ``"died"`` (its worker died on every attempt), ``"timeout"`` or ``"cancelled"``.
    value : Any
        The task's return value when ``done``, or when it returned past its time (``timeout``
        with ``seconds`` set).
    error : str or None
        One line saying what went wrong.
    attempts : int
        Times a worker started the task (more than 1 after a retry).
    seconds : float or None
        Wall time of the last attempt on its worker, from its start to its return (None when it
        did not return).
    worker : str or None
        Address of the worker that ran the last attempt.
    peak_mb : float or None
        Peak resident memory (MiB) of the worker process while it ran the task; includes the
        worker's own baseline. None when unknown (the task did not finish).
    peak_scope : str
        ``"task"`` when the peak was reset at the task's start (Linux), ``"worker"`` when it is
        the worker's lifetime peak.
    """

    index: int
    status: str
    value: Any = None
    error: str | None = None
    attempts: int = 0
    worker: str | None = None
    peak_mb: float | None = None
    peak_scope: str = "task"
    seconds: float | None = None


# --------------------------------------------------------------------------- inside a task


def reset_peak_rss() -> bool:
    """Reset this process's peak resident set size (Linux ``clear_refs`` 5); False if impossible."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def peak_rss_mb() -> float:
    """Peak resident memory of this process in MiB since the last :func:`reset_peak_rss`
    (``VmHWM``), else since it started (``ru_maxrss``, KiB on Linux)."""
    with contextlib.suppress(OSError, AttributeError):
        with open("/proc/self/status") as fh:
            found = re.search(r"^VmHWM:\s+(\d+)\s+kB", fh.read(), re.MULTILINE)
        if found:
            return int(found.group(1)) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _message(kind: str, data: dict[str, Any]) -> tuple[Any, dict[str, Any]] | None:
    """This worker and the event about its running task; None outside a worker."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):  # called directly, not as a task
        return None
    return worker, {"kind": kind, "key": worker.get_current_task(), "pid": os.getpid(), "worker": worker.address,
                    **data}


def report(kind: str, **data: Any) -> None:
    """Send ``data`` (plain values) about the running task to the client, as a Dask event; the
    client hands it to ``Engine.run(on_event=...)``. Delivered to the scheduler before it returns
    (the task may die next); does nothing outside a worker."""
    found = _message(kind, data)
    if found is not None:
        from distributed import get_client

        get_client().log_event(TOPIC, found[1])


def _kill_worker_process(dask_worker: Any) -> None:
    """Run on a worker's nanny (``Client.run(nanny=True)``): kill the worker process at once
    (SIGKILL: its task's thread cannot be stopped otherwise); the nanny starts a new one."""
    pid = getattr(getattr(getattr(dask_worker, "process", None), "process", None), "pid", None)
    if pid:
        os.kill(pid, signal.SIGKILL)


def _run_item(func: Callable[[Any], Any], setup: Callable[[], Any] | None, item: Any) -> tuple[Any, float, str, float]:
    """The task: ``setup()`` (not timed), then ``func(item)`` announced to the client; returns the
    value, the peak memory and the seconds from the announcement to the return."""
    if setup is not None:
        setup()
    scope = "task" if reset_peak_rss() else "worker"
    t0 = time.monotonic()
    found = _message("start", {})
    if found is not None:
        found[0].log_event(TOPIC, found[1])  # batched: no round trip
    value = func(item)
    return value, peak_rss_mb(), scope, time.monotonic() - t0


# --------------------------------------------------------------------------- client side


@dataclass
class _Running:
    """What the client knows of one submitted item."""

    index: int
    future: Any
    started: float | None = None  # time.monotonic() of the last start event (None: not running)
    attempts: int = 0
    pids: list[int] = field(default_factory=list)
    worker: str | None = None


class Engine:
    """Runs a function over items on a Dask cluster (context manager).

    Parameters
    ----------
    client : distributed.Client, optional
        Use this client's cluster; the engine neither configures nor closes it.
    workers : int, optional
        Worker processes of the local cluster started when neither ``client`` nor ``scheduler``
        is given (default: the number of cores). Each has one thread.
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:port``) whose workers run the tasks; the
        items must name files that those workers can reach.
    retries : int
        Extra attempts of a task that raises, and, on a cluster the engine starts, of a task whose
        worker dies (Dask's ``allowed-failures``); an external scheduler keeps its own setting.
    timeout : float, optional
        Seconds one task may run, from its start on a worker (queueing and ``setup`` excluded):
        past that it is cancelled and its worker restarted (the check runs every ``POLL``
        seconds, on the client's clock from the task's start event), and a task that returns
        having run longer ends ``timeout`` too.
    """

    def __init__(self, client: Any = None, *, workers: int | None = None, scheduler: str | None = None,
                 retries: int = 2, timeout: float | None = None) -> None:
        if client is not None and scheduler is not None:
            raise ValueError("give a client or a scheduler address, not both")
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self.client = client
        self.workers = workers
        self.scheduler = scheduler
        self.retries = retries
        self.timeout = timeout
        self._stack: contextlib.ExitStack | None = None
        self._local = False  # a local cluster started here: its nannies log in this process
        self._codes = ExitCodes()
        self._restarts: list[threading.Thread] = []  # workers being restarted after a timeout
        self._stopped: set[tuple[Any, int]] = set()  # (address, pid) of workers stopped after a timeout
        self._dashboard: str | None = None  # the served dashboard's link, "" for none (None: not asked)

    # ----------------------------------------------------------------- lifecycle

    def __enter__(self) -> Engine:
        import dask
        from distributed import Client, LocalCluster

        if self.client is not None:
            return self
        stack = contextlib.ExitStack()
        try:
            if self.scheduler is not None:
                self.client = stack.enter_context(Client(self.scheduler, timeout="10s"))
            else:
                stack.enter_context(dask_logs_routed(self._codes))
                # One task per single-threaded worker at a time (saturation 1.0): a worker
                # restarted after a timeout holds no other task.
                stack.enter_context(dask.config.set({"distributed.scheduler.allowed-failures": self.retries,
                                                     "distributed.scheduler.worker-saturation": 1.0}))
                with warnings.catch_warnings():  # 8787 taken: Dask takes a free port, dashboard_link says which
                    warnings.filterwarnings("ignore", message="Port .* is already in use", category=UserWarning)
                    cluster = stack.enter_context(LocalCluster(
                        n_workers=self.workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                        host="127.0.0.1", dashboard_address="127.0.0.1:8787"))
                self.client = stack.enter_context(Client(cluster))
                self._local = True
        except BaseException:
            stack.close()
            raise
        self._stack = stack
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._stack is not None:
            stack, self._stack = self._stack, None
            self.client, self._local, self._dashboard = None, False, None
            stack.close()

    @property
    def dashboard_link(self) -> str | None:
        """Address of the Dask dashboard (its pages need bokeh), None when the scheduler serves
        none (asked once: a running scheduler may have been started with ``--no-dashboard``)."""
        if self.client is None:
            return None
        if self._dashboard is None:
            self._dashboard = (getattr(self.client, "dashboard_link", None) if self._local
                               else served_dashboard(self.client)) or ""
        return self._dashboard or None

    @property
    def n_workers(self) -> int:
        """Workers connected now."""
        return len(self.client.scheduler_info().get("workers", {}))

    # ----------------------------------------------------------------- running

    def run(self, func: Callable[[Any], Any], items: Sequence[Any], *,
            on_event: Callable[[int, dict[str, Any]], None] | None = None,
            on_outcome: Callable[[Outcome], None] | None = None,
            setup: Callable[[], Any] | None = None) -> list[Outcome]:
        """Run ``func(item)`` for every item; returns one :class:`Outcome` per item, in order.

        ``func``, ``setup`` and the items must pickle (functions by reference: module-level
        functions of a module the workers can import). ``on_event(index, event)`` gets every
        event of an item's task (``event["kind"]`` is ``"start"`` or what the task passed to
        :func:`report`), ``on_outcome`` each outcome as it comes. ``setup()`` runs on the worker
        before each task starts, outside its time (say, imports that a fresh worker pays once).
        On an interruption the remaining tasks are cancelled.
        """
        if self.client is None:
            raise RuntimeError("Engine.run outside its 'with' block")
        from distributed import as_completed

        client, token = self.client, uuid.uuid4().hex[:12]
        events: queue.SimpleQueue = queue.SimpleQueue()
        client.subscribe_topic(TOPIC, lambda ev: events.put(ev[1]))
        keys = [f"houghcad-{token}-{i}" for i in range(len(items))]
        # One map, one message to the scheduler, however many items.
        futures = client.map(functools.partial(_run_item, func, setup), items, key=keys, retries=self.retries,
                             pure=False)
        running = {f.key: _Running(i, f) for i, f in enumerate(futures)}
        del futures
        done = as_completed([r.future for r in running.values()])
        outcomes: dict[int, Outcome] = {}
        interrupted = _InterruptFlag()
        try:
            while running:
                interrupted.check()
                busy = self._take_events(events, running, on_event)
                for future in done.next_batch(block=False) if done.has_ready() else []:
                    busy = True
                    state = running.get(future.key)
                    if state is not None and future.status not in _ENDED:
                        # It finished, then its result was lost with its worker before this
                        # loop took it ("lost"): Dask computes it again; wait for that.
                        state.started = None
                        done.add(future)
                        continue
                    if state is not None:
                        del running[future.key]
                        self._finish(self._outcome(state, future), outcomes, on_outcome)
                    future.release()  # its result would be recomputed if its worker died later
                busy |= self._expire(running, outcomes, on_outcome)
                if not busy:
                    time.sleep(POLL)
            interrupted.check()
        finally:
            interrupted.restore()
            client.unsubscribe_topic(TOPIC)
            if running:  # interrupted
                client.cancel([r.future for r in running.values()])
            self._wait_for_restarts()
        return [outcomes[i] for i in range(len(items))]

    @staticmethod
    def _finish(outcome: Outcome, outcomes: dict[int, Outcome], on_outcome: Callable | None) -> None:
        outcomes[outcome.index] = outcome
        if on_outcome is not None:
            on_outcome(outcome)

    def _take_events(self, events: queue.SimpleQueue, running: dict[str, _Running],
                     on_event: Callable[[int, dict[str, Any]], None] | None) -> bool:
        """Apply the events received since the last call; True if there were any."""
        got = False
        while True:
            try:
                event = events.get_nowait()
            except queue.Empty:
                return got
            got = True
            state = running.get(event.get("key"))
            if state is None:  # another run's task, or one already finished
                continue
            if event.get("kind") == "start":
                pid = int(event.get("pid", -1))
                # A start on a worker being stopped (delivered late): that attempt is lost, its
                # clock starts again with the next attempt.
                state.started = time.monotonic() if (event.get("worker"), pid) not in self._stopped else None
                state.worker = event.get("worker")
                state.attempts += 1
                state.pids.append(pid)
            if on_event is not None:
                on_event(state.index, event)

    def _outcome(self, state: _Running, future: Any) -> Outcome:
        """The outcome of a finished (or erred, or cancelled) future."""
        base = {"index": state.index, "attempts": max(1, state.attempts), "worker": state.worker}
        if future.status == "finished":
            value, peak, scope, seconds = future.result()
            if self.timeout is not None and seconds > self.timeout:  # it returned in the gap
                return Outcome(status="timeout", value=value, error=f"timeout after {self.timeout:g} s "
                               f"(it ran {seconds:.2f} s)", seconds=seconds, **base)
            return Outcome(status="done", value=value, peak_mb=peak, peak_scope=scope, seconds=seconds, **base)
        if future.status == "cancelled":
            return Outcome(status="cancelled", error="cancelled", **base)
        exc = future.exception() if future.status == "error" else None
        if type(exc).__name__ == "KilledWorker":
            # The scheduler's count: a worker killed at once may die before its start event arrives.
            deaths, pid = killed_worker(exc)
            base["attempts"] = max(base["attempts"], deaths or 0)
            return Outcome(status="died", error=self._death_message(state, deaths, pid), **base)
        if exc is None:  # Dask gave no error (not seen: run() waits for a lost result to be recomputed)
            return Outcome(status="died", error="worker lost the task without an error", **base)
        return Outcome(status="failed", error=_one_line(f"{type(exc).__name__}: {exc}"), **base)

    def _death_message(self, state: _Running, deaths: int | None, pid: int | None) -> str:
        """:func:`death_message` of ``deaths`` (else the attempts seen); the last worker's exit
        code is known on a local cluster the engine started."""
        pid = pid if pid is not None else (state.pids[-1] if state.pids else None)
        deadline = time.monotonic() + (EXIT_CODE_WAIT if self._local else 0.0)
        while pid is not None and pid not in self._codes.codes and time.monotonic() < deadline:
            time.sleep(POLL)  # the nanny may log the exit just after the scheduler gave up
        return death_message(deaths or state.attempts, self._codes.codes.get(pid) if pid is not None else None)

    def _expire(self, running: dict[str, _Running], outcomes: dict[int, Outcome],
                on_outcome: Callable | None) -> bool:
        """End the tasks past their time and stop them (their workers restart beside the loop);
        True if any."""
        if self.timeout is None:
            return False
        now = time.monotonic()
        # A task that returned meanwhile is judged by its own time on its worker, next turn.
        late = [(k, s) for k, s in running.items() if s.started is not None and now - s.started >= self.timeout
                and s.future.status not in _ENDED]
        for key, state in late:
            del running[key]
            if state.pids:
                self._stopped.add((state.worker, state.pids[-1]))
            for other in running.values():  # queued behind it on that worker: moved, not started
                if other.worker == state.worker:
                    other.started = None
            self._stop(state.future, state.worker)
            self._finish(Outcome(state.index, "timeout", error=f"timeout after {self.timeout:g} s",
                                 attempts=state.attempts, worker=state.worker, peak_mb=None), outcomes, on_outcome)
        return bool(late)

    def _stop(self, future: Any, worker: str | None) -> None:
        """Stop a task past its time, in a thread beside the loop (three round trips to the
        scheduler): its worker first stops taking tasks (else the scheduler would hand it the
        next one as soon as the task is cancelled, and the worker's end would count against that
        innocent task's attempts), then the task is cancelled, then its nanny kills the worker
        process at once (a graceful restart lets the task run on for seconds, taking a core from
        the others) and starts a new one. A worker without a nanny (``dask worker --no-nanny``)
        cannot be restarted: it is closed, and the batch goes on with the other workers."""
        client = self.client

        def stop() -> None:
            if worker is not None:
                with contextlib.suppress(Exception):
                    client.retire_workers([worker], close_workers=False, remove=False)
            with contextlib.suppress(Exception):
                client.cancel([future])
            if worker is not None:
                try:
                    killed = client.run(_kill_worker_process, workers=[worker], nanny=True)
                except Exception:
                    killed = {}
                if not killed:  # no nanny ran it
                    with contextlib.suppress(Exception):
                        client.retire_workers([worker], close_workers=True)

        thread = threading.Thread(target=stop, name="houghcad-engine-restart", daemon=True)
        thread.start()
        self._restarts.append(thread)

    def _wait_for_restarts(self) -> None:
        """Wait for the stopping of the tasks past their time (a run leaves none running)."""
        deadline = time.monotonic() + STOP_WAIT
        while self._restarts:
            self._restarts.pop().join(max(0.0, deadline - time.monotonic()))


def _one_line(text: str, limit: int = 500) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."
