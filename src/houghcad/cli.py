"""Command-line interface: ``houghcad segment | demo | evaluate | batch`` (batch: :mod:`.batchcli`).

Exit codes: 0 success, 2 bad input or usage (one line on stderr, prefixed
``houghcad: error:``, no traceback), 130 interrupted.  Any other exception is
a bug and propagates with its traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import importlib.resources
import json
import os
import re
import shutil
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from . import __version__
from .batch import truth_beside
from .cliopts import add_segment_options, path_text, positive_int, segment_options
from .errors import InputError
from .io import PointCloud, read_points, write_fit4cad_primitives, write_json
from .io.readers import describe_formats
from .report import summary_table

__all__ = ["main", "build_parser"]

PROG = "houghcad"
DEMO_DIR_DEFAULT = "houghcad-demo"


class _UsageError(Exception):
    """Bad command line; reported like an InputError."""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser that raises instead of printing usage and exiting."""

    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{message} (see '{self.prog} --help')")


def _version() -> str:
    """The version line, with how the numba kernels run (see :mod:`houghcad.kernels`)."""
    from .kernels import aot_loaded

    how = "compiled ahead of time" if aot_loaded() else "compiled by numba on first use"
    return f"{PROG} {__version__} (kernels {how})"


def build_parser() -> argparse.ArgumentParser:
    """The ``houghcad`` argument parser with its subcommands."""
    parser = _Parser(
        prog=PROG,
        description="Recognise planes, cylinders, cones, spheres and tori, and with --families all "
        "ellipsoids, helical, revolution and other complex surfaces, in 3-D point clouds of mechanical "
        "parts with Hough transforms.",
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("segment", help="segment a point cloud into primitives",
                       description=f"Segment a point cloud ({describe_formats()}) and write the "
                       "result as JSON.")
    p.add_argument("input", metavar="INPUT", type=path_text, help="point-cloud file")
    p.add_argument("-o", "--output", metavar="RESULT.json", type=path_text,
                   help="result file (default: <input stem>_segments.json in the current directory)")
    add_segment_options(p)
    p.add_argument("--fit4cad", metavar="DIR", type=path_text,
                   help="also write DIR/<input stem>_primitives.txt in the Fit4CAD ground-truth format")
    p.add_argument("--ply", metavar="OUT.ply", type=path_text,
                   help="also write the cloud as a coloured binary PLY with per-point segment, type and group "
                   "fields (for CloudCompare, MeshLab)")
    p.add_argument("--png", metavar="OUT.png", type=path_text, help="also draw four views coloured by type and by segment")
    p.add_argument("--report", metavar="OUT.html", type=path_text,
                   help="also write a self-contained HTML report: interactive 3-D view, tables, timings")
    p.add_argument("--trace", metavar="DIR", type=path_text,
                   help="also write the labels after every pass of the pipeline, one PLY per pass named "
                   "NN_PASS.ply, to see where a cloud goes wrong (DIR is created if needed)")
    p.add_argument("--jobs", type=positive_int, default=None, metavar="N",
                   help="processes for the independent work of the run (families, clusters); the result is the "
                   "same for every N (default: every available core)")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors (and no progress bar)")
    p.set_defaults(func=_cmd_segment)

    p = sub.add_parser("demo", help="segment the example part shipped with the package",
                       description="Segment the bundled demo part and write DIR/demo_part_segments.json, "
                       "the coloured cloud DIR/demo_part_segments.ply, the views DIR/demo_part_segments.png "
                       "and the report DIR/demo_part_report.html.")
    p.add_argument("-o", "--output", metavar="DIR", default=DEMO_DIR_DEFAULT, type=path_text,
                   help=f"output directory (default: ./{DEMO_DIR_DEFAULT})")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors (and no progress bar)")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("evaluate", help="compare a result with Fit4CAD ground truth",
                       description="Print the Fit4CAD classification measures (DSC first) and MFE statistics.")
    p.add_argument("result", metavar="RESULT.json", type=path_text, help="file written by 'houghcad segment'")
    p.add_argument("ground_truth", metavar="GROUND_TRUTH", type=path_text,
                   help="NAME_primitives.txt, or the cloud file NAME.txt/.ply/... next to it")
    p.add_argument("--maximal", action="store_true",
                   help="score the maximal primitives (the JSON's segments) instead of their faces "
                        "(each segment's connected parts, one per CAD face as in the ground truth)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=_cmd_evaluate)

    from .batchcli import add_batch_parser  # late: batchcli uses this module's helpers

    add_batch_parser(sub)
    return parser


# --------------------------------------------------------------------------- helpers


def _same_file(a: Path, b: Path) -> bool:
    """True when ``a`` and ``b`` name the same file (``b`` may not exist yet)."""
    try:
        if b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _check_output(path: Path, inputs: Sequence[Path], *, create_parent: bool = False) -> None:
    """Fail early, before a long run, on an output path that cannot be written."""
    for inp in inputs:
        if _same_file(inp, path):
            raise InputError(f"{path}: refusing to overwrite the input file")
    if path.is_dir():
        raise InputError(f"{path}: cannot write output (is a directory)")
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise InputError(f"{path}: cannot write output ({parent} is not a directory)")
    if not parent.exists() and not create_parent:
        raise InputError(f"{path}: cannot write output (directory {parent} does not exist)")


def _write(path: Path, writer: Callable[[Path, Any], None], payload: Any) -> None:
    """Run an (atomic) writer; OS errors become a one-line InputError."""
    try:
        writer(path, payload)
    except OSError as exc:
        raise InputError(f"{path}: cannot write output ({exc.strerror or exc})") from None


def _make_dir(directory: Path) -> None:
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{directory}: cannot create directory ({exc.strerror or exc})") from None


def _run_segmentation(cloud: PointCloud, *, quiet: bool = False, merge: bool = True, **options: Any):
    """Call :func:`houghcad.pipeline.segment` (imported late: it compiles with numba).

    A progress bar goes to stderr unless ``quiet`` or stderr is not a terminal.
    ``merge`` is passed only to a pipeline that has the association step. The result's
    ``options["input"]`` records :meth:`PointCloud.provenance` (the scan read, the rows left out).
    """
    import inspect

    from .pipeline import segment

    if "merge" in inspect.signature(segment).parameters:
        options["merge"] = merge
    with _progress_bar(quiet) as progress:
        result = segment(cloud.points, cloud.normals, source=cloud.source, progress=progress, **options)
    # Which rows of the file the indices refer to (the scan read, the rows left out): the
    # options are stored as they are, so the JSON layout (RESULT_VERSION) does not change.
    result.options["input"] = cloud.provenance()
    return result


@contextlib.contextmanager
def _progress_bar(quiet: bool):
    """Yield a ``progress(stage, fraction)`` callback drawing a tqdm bar on stderr, or None.

    Off when ``quiet`` or when stderr is not a TTY (logs, pipes, CI): a bar
    there is only noise.  The bar is removed when the run ends.
    """
    if quiet or not sys.stderr.isatty():
        yield None
        return
    from tqdm import tqdm

    # A terminal that reports no size (0 x 0, e.g. a bare pty) gets 80 x 24: tqdm
    # would draw nothing.
    size = shutil.get_terminal_size((80, 24))
    bar = tqdm(total=100, file=sys.stderr, leave=False, ncols=min(100, size.columns), nrows=size.lines,
               bar_format="{desc:<12}{percentage:3.0f}%|{bar}| {elapsed}")

    def progress(stage: str, fraction: float) -> None:
        # The pipeline reports a few dozen times per run: redraw on every call
        # (tqdm's rate limit would hide short stages).
        bar.set_description_str(stage, refresh=False)
        target = min(100, round(100.0 * float(fraction)))
        bar.update(max(0, target - bar.n))  # never backwards: a late report of an earlier stage
        bar.refresh()

    try:
        yield progress
    finally:
        bar.close()


def _write_views(cloud: PointCloud, result: Any, ply: Path | None, png: Path | None,
                 report: Path | None, done: Callable[[Path], None] = lambda path: None) -> None:
    """Write the optional coloured PLY, PNG views and HTML report, calling ``done`` after each
    (a big cloud's take seconds each)."""
    if ply is not None:
        from .io.writers import write_result_ply

        _write(ply, lambda p, r: write_result_ply(p, cloud.points, r, cloud.fields), result)
        done(ply)
    if png is not None:
        from .render import render_png

        _write(png, lambda p, r: render_png(p, cloud.points, r), result)
        done(png)
    if report is not None:
        from .htmlreport import write_html_report

        _write(report, lambda p, r: write_html_report(p, cloud.points, r), result)
        done(report)


def _wrote(quiet: bool) -> Callable[[Path], None]:
    """Say that an output is written, as soon as it is: the result first, then the summary, then
    each picture as it lands (a failure to write the result is the run's only line)."""
    return lambda path: _print(f"wrote {path}", quiet)


def _trace_dir(directory: Path, inp: Path) -> str:
    """The ``--trace`` folder, created now (before the run): the pipeline writes
    ``directory/NN_PASS.ply`` after each pass, over the points the passes run on (the
    subsample of a big cloud, with each point's input row); the input ``inp`` is never one."""
    if directory.exists() and not directory.is_dir():
        raise InputError(f"{directory}: --trace needs a directory")
    if re.fullmatch(r"\d{2}_\w+(\.\w+)*\.ply", inp.name) and _same_file(inp, directory / inp.name):
        raise InputError(f"{inp}: refusing to overwrite the input file with a --trace file (give another folder)")
    _make_dir(directory)
    return str(directory)


def _report_dropped(cloud: PointCloud, inp: Path, quiet: bool) -> None:
    """Say on stderr how many rows of the file the cloud left out (the result's
    ``options.input.dropped_rows`` lists them)."""
    if quiet:
        return
    if cloud.flagged:
        print(f"{PROG}: {inp}: left out {cloud.flagged} points the scanner flagged as invalid (no coordinates)",
              file=sys.stderr)
    if cloud.dropped:
        print(f"{PROG}: {inp}: left out {cloud.dropped} points with a NaN or infinite coordinate",
              file=sys.stderr)


def _print(text: str, quiet: bool) -> None:
    if not quiet:
        print(text, flush=True)  # each "wrote" line as its file lands, through a pipe too


def _load_family_files(paths: Sequence[str]) -> None:
    """Run each user file (as ``python FILE`` would) so that its
    ``houghcad.define_family`` calls register families; any failure is a
    one-line InputError."""
    import importlib.util

    for i, text in enumerate(paths):
        path = Path(text)
        if not path.is_file():
            raise InputError(f"{path}: no such family file")
        spec = importlib.util.spec_from_file_location(f"houghcad_user_families_{i}", path)
        if spec is None or spec.loader is None:
            raise InputError(f"{path}: cannot load family file (not a Python file)")
        module = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(module)
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None
        except Exception as exc:  # the user's code: any error is bad input
            raise InputError(f"{path}: cannot load family file ({type(exc).__name__}: {exc})") from None
        except SystemExit as exc:  # a script's exit() would end the run with no output and no word
            raise InputError(f"{path}: the family file exited (code {exc.code}) instead of defining families") \
                from None


# --------------------------------------------------------------------------- commands


def _cmd_segment(args: argparse.Namespace) -> int:
    with warnings.catch_warnings():  # for this command only: main() also runs inside scripts
        if args.quiet:  # quiet means a silent terminal: the libraries' warnings too
            warnings.simplefilter("ignore")
        return _segment(args)


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                  file: Any = None, line: str | None = None) -> None:
    """A warning as one ``houghcad: warning:`` line on stderr, not Python's file:line form."""
    _say("warning", message)


def _segment(args: argparse.Namespace) -> int:
    inp = Path(args.input)
    out = Path(args.output) if args.output else Path.cwd() / f"{inp.stem}_segments.json"
    prim = Path(args.fit4cad) / f"{inp.stem}_primitives.txt" if args.fit4cad else None

    views = {flag: Path(getattr(args, flag)) if getattr(args, flag) else None for flag in ("ply", "png", "report")}

    if args.family_file:
        from .families import select

        _load_family_files(args.family_file)
        select(args.families)  # unknown names fail now, not after reading the cloud
    options = segment_options(args)  # a bad --tolerance fails before the cloud is read
    cloud = read_points(inp, **options.read_kwargs())
    _report_dropped(cloud, inp, args.quiet)
    _check_output(out, [inp])
    if prim is not None:
        truth = truth_beside(inp)
        if truth is not None and _same_file(truth, prim):
            raise InputError(f"{prim}: refusing to overwrite the ground truth beside the input "
                             "(give --fit4cad another folder)")
        _check_output(prim, [inp, out], create_parent=True)
    taken = [out] + ([prim] if prim is not None else [])
    for flag, path in views.items():
        if path is None:
            continue
        for other in taken:  # two outputs on one path: the second would silently replace the first
            if _same_file(other, path):
                raise InputError(f"{path}: --{flag} names the same file as another output")
        _check_output(path, [inp])
        taken.append(path)

    kwargs = options.segment_kwargs()
    kwargs["n_jobs"] = args.jobs
    if args.trace:
        kwargs["trace"] = _trace_dir(Path(args.trace), inp)
    try:
        result = _run_segmentation(cloud, quiet=args.quiet, **kwargs)
    except OSError as exc:  # the run reads nothing: only the trace's files are written in it
        if not args.trace:
            raise
        raise InputError(f"{args.trace}: cannot write the trace ({exc.strerror or exc})") from None
    _write(out, write_json, result.to_dict())
    written = [out]
    if prim is not None:
        _make_dir(prim.parent)
        _write(prim, write_fit4cad_primitives, result.faces())
        written.append(prim)
    _print(summary_table(result), args.quiet)
    wrote = _wrote(args.quiet)
    for path in written:
        wrote(path)
    _write_views(cloud, result, views["ply"], views["png"], views["report"], wrote)
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    resource = importlib.resources.files("houghcad") / "data" / "demo_part.ply"
    if not resource.is_file():
        raise InputError(f"{resource}: demo data file is missing from the installed package")
    outdir = Path(args.output)
    out = outdir / "demo_part_segments.json"
    ply, png, report = (outdir / name for name in
                        ("demo_part_segments.ply", "demo_part_segments.png", "demo_part_report.html"))
    for path in (out, ply, png, report):
        _check_output(path, [], create_parent=True)

    with importlib.resources.as_file(resource) as path:
        cloud = read_points(path)
    result = _run_segmentation(cloud, quiet=args.quiet)
    _make_dir(outdir)
    _write(out, write_json, result.to_dict())
    _print(summary_table(result), args.quiet)
    wrote = _wrote(args.quiet)
    wrote(out)
    _write_views(cloud, result, ply, png, report, wrote)
    return 0


def _format_evaluation(report: dict[str, Any]) -> str:
    """Measures (DSC first), MFE statistics and segment counts as text lines."""
    measures = report["measures"]
    order = ["DSC"] + [k for k in measures if k != "DSC"]
    lines = [f"{name:<5}{float(measures[name]):8.4f}" for name in order if name in measures]
    mfe = report.get("mfe", {})
    if mfe:
        lines.append("MFE  " + "  ".join(f"{k} {float(v):.3e}" for k, v in mfe.items()))
    if "n_gt" in report and "n_pred" in report:
        unit = "maximal primitives" if report.get("scored") == "maximal" else "faces"
        lines.append(f"segments: {report['n_gt']} in ground truth, {report['n_pred']} predicted {unit} "
                     f"(ratio {report['n_pred'] / max(report['n_gt'], 1):.2f})")
    return "\n".join(lines)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluate import evaluate_files

    report = evaluate_files(args.result, args.ground_truth, maximal=args.maximal)
    if args.json:
        measures = report["measures"]
        ordered = {"DSC": measures["DSC"], **measures} if "DSC" in measures else measures
        print(json.dumps({**report, "measures": ordered}, indent=2, default=float))
    else:
        print(_format_evaluation(report))
    return 0


# --------------------------------------------------------------------------- entry point


def _error(message: str) -> None:
    _say("error", message)


def _say(kind: str, message: object) -> None:
    """``houghcad: KIND: message`` on stderr, in one line whatever the message contained."""
    print(f"{PROG}: {kind}: {' '.join(str(message).split())}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0, 2 for bad input/usage, 130 on Ctrl-C)."""
    parser = build_parser()
    try:
        try:
            args = parser.parse_args(argv)
        except _UsageError as exc:
            _error(str(exc))
            return 2
        except SystemExit as exc:  # --help / --version print, then "exit"
            return exc.code if isinstance(exc.code, int) else 0
        with warnings.catch_warnings():  # for this command only: main() also runs inside scripts
            warnings.showwarning = _show_warning
            return args.func(args)
    except InputError as exc:
        _error(str(exc))
        return 2
    except KeyboardInterrupt:
        # Outputs are written whole or not at all: nothing partial is left.
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of our output went away (`houghcad segment ... | head`):
        # the results are written already; stop quietly. Python would print
        # the error again when it flushes stdout at exit, so point it elsewhere.
        _silence_stdout()
        return 0
    except OSError as exc:
        # Our own files' errors are InputErrors already: this is the terminal's
        # output failing (`> /dev/full`), after the files were written.
        _silence_stdout()
        _error(f"cannot write to standard output ({exc.strerror or exc})")
        return 2


def _silence_stdout() -> None:
    """Point stdout at the null device: Python flushes it again at exit."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())


def run() -> int:
    """The ``houghcad`` command: :func:`main` in a process that exits right after it.

    Exiting, the interpreter's last cyclic garbage collection walks every object the run made
    (numba's compiled code, scipy's and ours): about 0.2 s of a 2 s command on a Fit4CAD cloud.
    Nothing needs it: the outputs are written and closed, and the workers' pool is closed by
    then (``atexit`` handlers still run). Freezing the collected objects skips it. Not in
    :func:`main`, which tests and scripts call in long-lived processes.
    """
    code = main()
    gc.freeze()
    return code


if __name__ == "__main__":
    sys.exit(run())
