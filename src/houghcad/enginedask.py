"""What :class:`houghcad.engine.Engine` learns from Dask outside its API, and Dask's log kept to
itself: the exit codes of dead workers (Dask says them only in its nannies' log lines), whether a
scheduler serves its dashboard (its address is reported either way), and Dask's log records
routed to the logger ``houghcad.engine`` instead of stderr while a cluster the engine started runs.
"""

from __future__ import annotations

import contextlib
import http.client
import logging
import os
import re
import urllib.error
import urllib.request
from collections.abc import Iterator
from typing import Any

__all__ = ["LOG", "ExitCodes", "dask_logs_routed", "death_message", "killed_worker", "served_dashboard"]

#: Where Dask's records go while a cluster the engine started runs. Silent unless the application
#: configures logging (the NullHandler stops Python's last-resort print to stderr).
LOG = logging.getLogger("houghcad.engine")
LOG.addHandler(logging.NullHandler())
#: Seconds to wait for a scheduler's HTTP server to say whether it serves the dashboard.
DASHBOARD_WAIT = 2.0
_DEATH = re.compile(r"Worker process (\d+) (?:exited with status|was killed by signal) (\d+)")


class ExitCodes(logging.Handler):
    """Collects ``pid -> exit code`` of the worker processes that the nannies of a local cluster
    (in this process) saw die (negative: killed by that signal)."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.codes: dict[int, int] = {}

    def emit(self, record: logging.LogRecord) -> None:
        found = _DEATH.search(record.getMessage())
        if found:
            code = int(found.group(2))
            self.codes[int(found.group(1))] = -code if "signal" in record.getMessage() else code


class _Route(logging.Handler):
    """Hands Dask's records to :data:`LOG` (they keep their own logger's name)."""

    def emit(self, record: logging.LogRecord) -> None:
        LOG.handle(record)


@contextlib.contextmanager
def dask_logs_routed(codes: ExitCodes) -> Iterator[None]:
    """While a cluster that the engine started runs: Dask's records of this process go to
    :data:`LOG`, not to stderr (every task's end is an Outcome, and the caller says it: a line
    such as "Task ... marked as failed because 2 workers died" would only repeat it, raw); its
    workers log only what is critical; the nannies' exit codes go to ``codes``."""
    dist, nanny = logging.getLogger("distributed"), logging.getLogger("distributed.nanny")
    saved = dist.handlers[:], dist.level, nanny.level, nanny.propagate, os.environ.get("DASK_LOGGING__DISTRIBUTED")
    route = _Route()
    dist.handlers[:] = [route]  # Dask's own handler prints to stderr
    dist.setLevel(logging.WARNING)
    nanny.setLevel(logging.INFO)  # the exit codes are INFO lines
    nanny.propagate = False
    nanny.addHandler(codes)
    os.environ["DASK_LOGGING__DISTRIBUTED"] = "critical"  # read by the spawned workers
    try:
        yield
    finally:
        nanny.removeHandler(codes)
        dist.handlers[:] = saved[0]
        dist.setLevel(saved[1])
        nanny.setLevel(saved[2])
        nanny.propagate = saved[3]
        if saved[4] is None:
            os.environ.pop("DASK_LOGGING__DISTRIBUTED", None)
        else:
            os.environ["DASK_LOGGING__DISTRIBUTED"] = saved[4]


def death_message(deaths: int, code: int | None) -> str:
    """``worker died (exit code N)``, ``worker died K times (exit code N)`` (the last death's
    code), without the code when it is unknown."""
    times = f" {deaths} times" if deaths > 1 else ""
    if code is None:
        return f"worker died{times}"
    hint = " (SIGKILL: out of memory?)" if code == -9 else ""
    return f"worker died{times} (exit code {code}){hint}"


def killed_worker(exc: BaseException) -> tuple[int | None, int | None]:
    """Deaths and the last dead worker's pid of Dask's ``KilledWorker`` (None when unknown): the
    scheduler gives up after ``allowed-failures + 1`` deaths."""
    allowed = getattr(exc, "allowed_failures", None)
    pid = getattr(getattr(exc, "last_worker", None), "pid", None)
    return (allowed + 1 if isinstance(allowed, int) else None), (pid if isinstance(pid, int) else None)


def served_dashboard(client: Any) -> str | None:
    """The client's dashboard link if its scheduler serves that page. A scheduler started with
    ``--no-dashboard`` still runs an HTTP server and reports its port as the dashboard's, so
    the link is asked for: a HEAD request answered 404, or not answered, means no dashboard (the
    page's handler answers HEAD with 405, or 200: nothing is rendered)."""
    try:
        link = client.dashboard_link
    except (AttributeError, KeyError, ValueError):  # KeyError: no HTTP server at all
        return None
    if not link:
        return None
    try:
        with urllib.request.urlopen(urllib.request.Request(link, method="HEAD"), timeout=DASHBOARD_WAIT):
            return link
    except urllib.error.HTTPError as exc:
        return None if exc.code == 404 else link
    except (OSError, ValueError, http.client.HTTPException):
        return None
