"""``houghcad batch``: segment many clouds on a Dask cluster (the command line of :mod:`.batch`).

Exit codes: 0 when every input is ``ok`` or ``skipped``, 1 when any is ``error``, 2 for a usage
error or an input that names nothing (one line, before any cloud runs), 130 when interrupted
(the finished clouds' outputs and the summary of them are whole).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .batch import OUTPUT_NAMES, BatchRow
from .cliopts import add_segment_options, non_negative_int, path_text, positive_int, segment_options
from .errors import InputError

__all__ = ["add_batch_parser", "Progress"]


def _seconds(text: str) -> float:
    """``--timeout``: a positive number of seconds."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, got {text}")
    return value


def add_batch_parser(sub: Any) -> None:
    """Add the ``batch`` subcommand to the ``houghcad`` subparsers ``sub``."""
    names = ", ".join(f"<stem>{OUTPUT_NAMES[k]}" for k in ("fit4cad", "ply", "png", "report"))
    p = sub.add_parser(
        "batch", help="segment many point clouds on a Dask cluster",
        description="Segment every point cloud named by INPUT (files, folders, glob patterns) as "
        "'houghcad segment' would, on a local Dask cluster or on a running one, and write "
        "OUTDIR/<stem>_segments.json per cloud, OUTDIR/summary.csv and OUTDIR/index.html. "
        f"Optional outputs per cloud, in OUTDIR: {names}.")
    p.add_argument("inputs", nargs="+", metavar="INPUT", type=path_text,
                   help="point-cloud file, folder (the clouds directly inside) or glob pattern (quote it; ** recurses)")
    p.add_argument("-o", "--output", metavar="OUTDIR", required=True, type=path_text, help="output folder (created if needed)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="address of a running Dask scheduler, e.g. tcp://host:8786; its workers must reach the "
                   "INPUT and OUTDIR paths (default: start a local cluster)")
    p.add_argument("--workers", type=positive_int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--retries", type=non_negative_int, default=2, metavar="N",
                   help="extra attempts for a cloud whose worker died (local cluster) or that hit an I/O error "
                   "(default: 2)")
    p.add_argument("--timeout", type=_seconds, default=None, metavar="SECONDS",
                   help="time one cloud may run on its worker, measured there from when the cloud starts (reading, "
                   "segmenting, writing, scoring; waiting for a free worker does not count): a cloud still running "
                   "past it is stopped within about 0.1 s and its worker restarted, and a cloud that finished "
                   "having run longer is an error too (its outputs are removed); an ok row always ran within "
                   "SECONDS (default: none)")
    p.add_argument("--force", action="store_true",
                   help="run every cloud, even those whose outputs are already there and newer than the input")
    add_segment_options(p)
    p.add_argument("--fit4cad", action="store_true", help="also write OUTDIR/<stem>_primitives.txt (Fit4CAD format)")
    p.add_argument("--ply", action="store_true", help="also write the coloured cloud OUTDIR/<stem>_segments.ply")
    p.add_argument("--png", action="store_true", help="also draw the views OUTDIR/<stem>_segments.png")
    p.add_argument("--report", action="store_true", help="also write the HTML report OUTDIR/<stem>_report.html")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="print nothing but the clouds that fail (no progress, no dashboard address)")
    p.set_defaults(func=_cmd_batch)


class Progress:
    """Progress of a batch on stderr: a tqdm bar over the clouds (done, failed, running, time
    left) on a terminal, else one line per cloud; ``quiet`` prints only the failures."""

    def __init__(self, quiet: bool = False, stream: Any = None) -> None:
        self.quiet = quiet
        self.stream = stream if stream is not None else sys.stderr
        self.bar: Any = None
        self.total = self.done = self.failed = 0
        self.running: set[str] = set()

    def begin(self, total: int, skipped: Sequence[BatchRow], dashboard: str | None) -> None:
        self.total, self.done = total, len(skipped)
        if self.quiet:
            return
        if dashboard:
            self._line(f"Dask dashboard: {dashboard}{_bokeh_note()}")
        if self.stream.isatty():
            from tqdm import tqdm

            size = shutil.get_terminal_size((80, 24))
            self.bar = tqdm(total=total, initial=len(skipped), unit="cloud", file=self.stream,
                            ncols=min(120, size.columns), dynamic_ncols=False)
            self._postfix()
        else:
            for k, row in enumerate(skipped, 1):
                self._line(f"[{k}/{total}] skipped  {row.input}")

    def started(self, name: str) -> None:
        self.running.add(name)
        self._postfix()

    def finished(self, row: BatchRow) -> None:
        self.running.discard(row.input)
        self.done += 1
        self.failed += row.status == "error"
        if row.status == "error":
            # An input error's message starts with the file's name already.
            what = row.error if (row.error or "").startswith(row.input) else f"{row.input}: {row.error}"
            self._line(f"[{self.done}/{self.total}] error    {what}", always=True)
        elif not self.quiet and self.bar is None:
            self._line(f"[{self.done}/{self.total}] {row.status:<8} {row.input}  {row.n_points} points  "
                       f"{row.n_segments} segments  {row.seconds:.1f} s")
        if self.bar is not None:
            self.bar.update(1)
            self._postfix()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def _postfix(self) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(f"failed {self.failed}, running {len(self.running)}")

    def _line(self, text: str, always: bool = False) -> None:
        if self.quiet and not always:
            return
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)


def _bokeh_note() -> str:
    import importlib.util

    return "" if importlib.util.find_spec("bokeh") else " (the page needs bokeh: pip install 'bokeh>=3.1')"


def _cmd_batch(args: argparse.Namespace) -> int:
    from .batch import batch

    if args.scheduler is not None and not args.scheduler.strip():
        raise InputError("--scheduler needs an address, e.g. tcp://host:8786")
    if args.scheduler and args.workers is not None:
        raise InputError("--workers sets the size of the local cluster: not with --scheduler")
    options = segment_options(args)
    progress = Progress(quiet=args.quiet)
    t0 = time.monotonic()
    try:
        rows = batch(args.inputs, args.output, scheduler=args.scheduler, workers=args.workers,
                     retries=args.retries, timeout=args.timeout, force=args.force, fit4cad=args.fit4cad,
                     ply=args.ply, png=args.png, report=args.report, progress=progress,
                     family_files=args.family_file, **options.segment_kwargs(), **options.read_kwargs())
    finally:
        progress.close()
    counts = {s: sum(r.status == s for r in rows) for s in ("ok", "skipped", "error")}
    if not args.quiet:
        out = Path(args.output)
        print(f"{len(rows)} clouds: {counts['ok']} ok, {counts['skipped']} skipped, {counts['error']} error "
              f"in {time.monotonic() - t0:.1f} s; wrote {out / 'summary.csv'} and {out / 'index.html'}")
    return 1 if counts["error"] else 0
