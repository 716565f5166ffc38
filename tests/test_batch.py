"""Tests of houghcad.batch and `houghcad batch` on real Dask clusters (small synthetic clouds)."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import houghcad
from houghcad import synth
from houghcad.batch import MEASURES, BatchRow, CloudJob, SegmentOptions, segment_cloud
from houghcad.batchcli import Progress
from houghcad.cli import main
from houghcad.io import write_points_ply

N_POINTS = 2000
SEGMENT_OPTIONS = ["--seed", "1", "--no-merge"]


def _write_fit4cad_cloud(path: Path, points: np.ndarray) -> None:
    body = "\n".join(f"[{x:.9g}, {y:.9g}, {z:.9g}]," for x, y, z in points)
    path.write_text(f"Points:=[\n{body}\n];\n")


@pytest.fixture(scope="module")
def clouds(tmp_path_factory) -> Path:
    """Five synthetic parts (PLY, and Fit4CAD text with its ground truth), a corrupt PLY and a
    README (not a cloud)."""
    folder = tmp_path_factory.mktemp("clouds")
    for i in range(5):
        cloud = synth.block_with_hole_and_slot(seed=i, n_points=N_POINTS)
        if i % 2:
            _write_fit4cad_cloud(folder / f"part{i}.txt", cloud.points)
            synth.write_fit4cad_segments(cloud, folder / f"part{i}_primitives.txt")
        else:
            write_points_ply(folder / f"part{i}.ply", cloud.points)
    (folder / "broken.ply").write_text("ply\nformat ascii 1.0\nelement vertex 30\nproperty float x\nend_header\n1\n")
    (folder / "README.md").write_text("Five synthetic parts.\n")
    return folder


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def first_run(clouds: Path, tmp_path_factory) -> tuple[int, Path, str, str, float]:
    """`houghcad batch FOLDER -o OUT --workers 2 ...` once: exit code, OUT, stdout, stderr, seconds."""
    out = tmp_path_factory.mktemp("batch") / "out"
    t0 = time.monotonic()
    code, stdout, stderr = _run(["batch", str(clouds), "-o", str(out), "--workers", "2", "--fit4cad", "--report",
                                 *SEGMENT_OPTIONS])
    return code, out, stdout, stderr, time.monotonic() - t0


def _summary(out: Path) -> tuple[list[dict[str, str]], list[list[str]]]:
    """The cloud rows of summary.csv, and its closing '# ' lines."""
    lines = (out / "summary.csv").read_text().splitlines()
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    return rows, [next(csv.reader([line])) for line in lines if line.startswith("#")]


def _result(path: Path) -> dict:
    data = json.loads(path.read_text())
    data.pop("timing")  # run-to-run times
    return data


# --------------------------------------------------------------------------- a folder on a local cluster


def test_folder_gives_one_row_per_cloud_and_exit_1_for_the_corrupt_file(first_run, clouds: Path):
    code, out, stdout, stderr, seconds = first_run
    assert code == 1, stderr
    rows, closing = _summary(out)
    assert [r["input"] for r in rows] == [str(clouds / n) for n in
                                          ("broken.ply", "part0.ply", "part1.txt", "part2.ply", "part3.txt", "part4.ply")]
    broken, parts = rows[0], rows[1:]
    assert broken["status"] == "error" and "broken.ply" in broken["error"] and "\n" not in broken["error"]
    assert broken["DSC"] == "" and broken["n_points"] == ""
    for r in parts:
        assert r["status"] == "ok" and r["error"] == "", r
        assert int(r["n_points"]) == N_POINTS and int(r["n_segments"]) >= 8 and float(r["seconds"]) > 0
        assert 0 <= int(r["unsegmented"]) < N_POINTS / 10
    with_gt = [r for r in parts if r["input"].endswith(".txt")]
    assert all(float(r["DSC"]) > 0.8 for r in with_gt) and all(r["DSC"] == "" for r in parts if r not in with_gt)
    dsc = [float(r["DSC"]) for r in with_gt]
    assert [c[0] for c in closing] == ["# mean over 2 clouds", "# median over 2 clouds"]
    assert float(closing[0][7]) == pytest.approx(np.mean(dsc), abs=1e-5)
    assert "6 clouds: 5 ok, 0 skipped, 1 error" in stdout
    assert "Dask dashboard: http://127.0.0.1:" in stderr and "[6/6]" in stderr  # one line per cloud off a TTY
    assert not list(out.glob(".*.tmp"))


def test_each_result_equals_segment_with_the_same_options(first_run, clouds: Path, tmp_path: Path):
    _, out, *_ = first_run
    for cloud in sorted(clouds.glob("part*")):
        if cloud.name.endswith("_primitives.txt"):
            continue
        mine = tmp_path / f"{cloud.stem}.json"
        assert main(["segment", str(cloud), "-o", str(mine), "--fit4cad", str(tmp_path), "-q", *SEGMENT_OPTIONS]) == 0
        assert _result(out / f"{cloud.stem}_segments.json") == _result(mine), cloud.name
        prim = f"{cloud.stem}_primitives.txt"
        assert (out / prim).read_text() == (tmp_path / prim).read_text()
        assert (out / f"{cloud.stem}_report.html").stat().st_size > 1000
    evaluated = json.loads(_run(["evaluate", str(out / "part1_segments.json"), str(clouds / "part1.txt"),
                                 "--json"])[1])["measures"]["DSC"]
    row = next(r for r in _summary(out)[0] if r["input"].endswith("part1.txt"))
    assert float(row["DSC"]) == pytest.approx(evaluated, abs=1e-5)  # what `houghcad evaluate` says


def test_index_is_self_contained_sortable_and_links_relative(first_run):
    _, out, *_ = first_run
    page = (out / "index.html").read_text()
    assert "http://" not in page and "https://" not in page and "<script src" not in page
    assert 'addEventListener("click"' in page and "aria-sort" in page
    links = [part.split('"', 1)[0] for part in page.split('href="')[1:]]
    assert len(links) == 5 * 3 and all(not Path(link).is_absolute() and "/" not in link for link in links)
    assert all((out / link).is_file() for link in links)
    assert "part0_report.html" in links and "<td" in page and "broken.ply" in page


def test_rerun_skips_then_force_on_one_worker_gives_the_same_results(first_run, clouds: Path, tmp_path: Path):
    _, first, *_ = first_run
    out = tmp_path / "out"
    shutil.copytree(first, out)
    argv = ["batch", str(clouds / "part0.ply"), str(clouds / "part1.txt"), "-o", str(out), "--fit4cad", "--report",
            *SEGMENT_OPTIONS]
    code, stdout, _ = _run(argv)
    rows, _ = _summary(out)
    before = {r["input"]: r for r in _summary(first)[0]}
    assert code == 0 and [r["status"] for r in rows] == ["skipped", "skipped"], stdout
    for r in rows:  # the figures of the earlier run are kept
        assert r["n_segments"] == before[r["input"]]["n_segments"] and r["DSC"] == before[r["input"]]["DSC"]
    os.utime(clouds / "part1.txt")  # a newer input runs again
    (out / "part0_report.html").unlink()  # and so does a cloud with an output missing
    code, *_ = _run([*argv, "--workers", "1"])
    assert code == 0 and [r["status"] for r in _summary(out)[0]] == ["ok", "ok"]
    code, *_ = _run([*argv, "--force", "--workers", "1"])
    assert code == 0 and [r["status"] for r in _summary(out)[0]] == ["ok", "ok"]
    for stem in ("part0", "part1"):  # one worker or two: the same results
        assert _result(out / f"{stem}_segments.json") == _result(first / f"{stem}_segments.json")


def test_skipped_clouds_are_scored_again_from_their_saved_results(first_run, clouds: Path, tmp_path: Path):
    """A batch of one cloud into OUTDIR wrote a summary.csv listing that cloud alone; the next
    full batch's skipped rows then lost their measures and '# mean' averaged the one cloud left
    (and so after deleting summary.csv). A skipped cloud is scored from its saved result."""
    _, first, *_ = first_run
    out = tmp_path / "out"
    shutil.copytree(first, out)
    parts = [str(clouds / n) for n in ("part0.ply", "part1.txt", "part2.ply", "part3.txt", "part4.ply")]
    options = ["-o", str(out), "--fit4cad", "--report", *SEGMENT_OPTIONS]
    before = {r["input"]: r for r in _summary(first)[0]}
    first_closing = _summary(first)[1]
    assert _run(["batch", parts[1], *options])[0] == 0
    assert [r["input"] for r in _summary(out)[0]] == [parts[1]]
    for case in ("after a batch of one cloud", "without summary.csv"):
        code, stdout, _ = _run(["batch", *parts, *options])  # all up to date: no cluster starts
        rows, closing = _summary(out)
        assert code == 0 and [r["status"] for r in rows] == ["skipped"] * 5, (case, stdout)
        for r in rows:
            for column in ("n_points", "n_segments", "unsegmented", "error", *MEASURES):
                assert r[column] == before[r["input"]][column], (case, r["input"], column)
        assert sum(bool(r["DSC"]) for r in rows) == 2
        assert closing == first_closing, case  # '# mean over 2 clouds', the same figures
        (out / "summary.csv").unlink()
    page = (out / "index.html").read_text()
    assert "mean over 2 clouds" in page


def test_a_saved_result_that_cannot_be_read_is_run_again(clouds: Path, tmp_path: Path):
    from houghcad.batch import plan

    (tmp_path / "part1_segments.json").write_text('{"n_points": 2000, "segments": [{"id": 0')  # cut short
    (tmp_path / "part3_segments.json").write_text(json.dumps(
        {"n_points": N_POINTS, "segments": [{"id": 0, "type": "plane"}], "unsegmented": []}))  # no indices
    planned = plan([str(clouds / "part1.txt"), str(clouds / "part3.txt")], tmp_path, SegmentOptions())
    assert [row for _, row in planned] == [None, None]


def test_a_cloud_that_returned_past_its_timeout_is_an_error_with_no_outputs(tmp_path: Path):
    from houghcad.batch import _finished
    from houghcad.engine import Outcome

    job = CloudJob(str(tmp_path / "a.ply"), "a.ply", str(tmp_path), "a", ("report", "json"), SegmentOptions())
    for name in ("a_report.html", "a_segments.json"):
        (tmp_path / name).write_text("{}")
    late = BatchRow("a.ply", "ok", 10, 1, 0, 1.19, outputs=("a_report.html", "a_segments.json"))
    rows: dict[int, BatchRow] = {}
    _finished(None, rows, 0, job, Outcome(0, "timeout", value=late, error="timeout after 1 s (it ran 1.20 s)",
                                          seconds=1.2))
    assert rows[0].status == "error" and rows[0].error == "timeout after 1 s (it ran 1.20 s)"
    assert rows[0].seconds == 1.2 and rows[0].outputs == ()
    assert not (tmp_path / "a_segments.json").exists() and not (tmp_path / "a_report.html").exists()


def test_timeout_help_says_what_it_bounds():
    code, stdout, _ = _run(["batch", "--help"])
    text = " ".join(stdout.split())
    assert code == 0 and "measured there from when the cloud starts" in text and "within about 0.1 s" in text


# --------------------------------------------------------------------------- a worker killed mid-batch


def dying_segment_cloud(job: CloudJob) -> BatchRow:
    """segment_cloud, except that the first task of the batch kills its worker process."""
    try:
        fd = os.open(Path(job.out_dir) / ".killed", os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return segment_cloud(job)
    os.write(fd, job.stem.encode())
    os.close(fd)
    os._exit(9)


def test_a_worker_killed_mid_batch_still_gives_every_cloud_ok(first_run, clouds: Path, tmp_path: Path):
    _, first, *_ = first_run
    inputs = [str(clouds / n) for n in ("part0.ply", "part1.txt", "part2.ply")]
    # A Tolerances object is taken as Segmenter takes it (the defaults: the same results).
    rows = houghcad.batch(inputs, tmp_path, workers=2, retries=1, task=dying_segment_cloud, seed=1, merge=False,
                          tolerances=houghcad.Tolerances())
    assert (tmp_path / ".killed").is_file()  # a worker did die
    assert all(isinstance(r, BatchRow) for r in rows) and [r.status for r in rows] == ["ok"] * 3, rows
    assert all(r.peak_mb and r.peak_mb > 50 for r in rows)
    for stem in ("part0", "part1", "part2"):
        assert _result(tmp_path / f"{stem}_segments.json") == _result(first / f"{stem}_segments.json")


# --------------------------------------------------------------------------- refused before starting


def test_same_stem_in_two_folders_is_refused_before_starting(clouds: Path, tmp_path: Path):
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(clouds / "part0.ply", other / "part0.ply")
    out = tmp_path / "out"
    code, stdout, stderr = _run(["batch", str(clouds / "part0.ply"), str(other), "-o", str(out)])
    assert code == 2 and stdout == "" and stderr.count("\n") == 1
    assert stderr.startswith("houghcad: error: ") and "part0_segments.json" in stderr
    assert not out.exists()


@pytest.mark.parametrize("extra,word", [
    (["--workers", "0"], "--workers"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),
    (["--scheduler", ""], "--scheduler needs an address"),
    (["--scheduler", "tcp://"], "cannot start the batch"),
    (["--tolerance", "recognition.neighbours=0"], "must be positive"),
    (["--families", "plane,blob"], "blob"),
    (["--tolerance", "recognition.nonsense=1"], "nonsense"),
    (["--timeout", "-3"], "--timeout"),
    (["--epsilon", "2"], "--epsilon"),
    (["--fit4cad", "somewhere"], "somewhere"),  # a flag in batch: the outputs go to OUTDIR
])
def test_usage_errors_exit_2_with_one_line(clouds: Path, tmp_path: Path, extra, word):
    code, stdout, stderr = _run(["batch", str(clouds / "part0.ply"), "-o", str(tmp_path / "out"), *extra])
    assert code == 2 and stdout == "" and stderr.count("\n") == 1, stderr
    assert stderr.startswith("houghcad: error: ") and word in stderr and "Traceback" not in stderr
    assert not (tmp_path / "out").exists()


def test_inputs_that_name_nothing_exit_2(clouds: Path, tmp_path: Path):
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "empty").mkdir()
    cases = [([str(tmp_path / "nope.ply")], "no such file"), ([str(tmp_path / "empty")], "no point-cloud file"),
             ([str(clouds / "*.xyz")], "matches"), ([str(clouds / "part0.ply"), "-o", str(tmp_path / "a_file")],
                                                   "not a folder")]
    for args, word in cases:
        argv = ["batch", *args] if "-o" in args else ["batch", *args, "-o", str(tmp_path / "out")]
        code, _, stderr = _run(argv)
        assert code == 2 and word in stderr and stderr.count("\n") == 1, (args, stderr)
    assert _run(["batch", str(clouds)])[0] == 2  # -o is required


def test_patterns_and_folders_skip_companions_and_duplicates(clouds: Path):
    from houghcad.batch import expand_inputs

    found = expand_inputs([str(clouds / "part*"), str(clouds / "part0.ply"), str(clouds)])
    names = [Path(d).name for d, _ in found]
    assert names == ["part0.ply", "part1.txt", "part2.ply", "part3.txt", "part4.ply", "broken.ply"]


def test_fit4cad_outputs_into_the_clouds_folder_would_replace_their_ground_truth(clouds: Path):
    truth = (clouds / "part1_primitives.txt").read_bytes()
    code, _, stderr = _run(["batch", str(clouds / "part1.txt"), "-o", str(clouds), "--fit4cad"])
    assert code == 2 and stderr.count("\n") == 1 and "part1_primitives.txt" in stderr, stderr
    assert "refusing to overwrite an input" in stderr
    assert (clouds / "part1_primitives.txt").read_bytes() == truth
    assert not (clouds / "part1_segments.json").exists()


def test_a_folder_scan_skips_the_batchs_own_summary(tmp_path: Path):
    from houghcad.batch import expand_inputs

    write_points_ply(tmp_path / "a.ply", synth.block_with_hole_and_slot(seed=0, n_points=300).points)
    (tmp_path / "summary.csv").write_text("input,status\na.ply,ok\n")
    (tmp_path / "points.csv").write_text("0,0,0\n1,0,0\n0,1,0\n")
    assert [Path(d).name for d, _ in expand_inputs([str(tmp_path)])] == ["a.ply", "points.csv"]


# --------------------------------------------------------------------------- progress


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_on_a_terminal_and_lines_elsewhere():
    ok = BatchRow("a.ply", "ok", n_points=100, n_segments=3, unsegmented=0, seconds=1.5)
    bad = BatchRow("b.ply", "error", error="b.ply: file is empty")
    term = _Terminal()
    p = Progress(stream=term)
    p.begin(3, [BatchRow("c.ply", "skipped")], "http://127.0.0.1:8787/status")
    p.started("a.ply")
    p.started("b.ply")
    p.finished(ok)
    p.finished(bad)
    p.close()
    text = term.getvalue()
    assert "Dask dashboard: http://127.0.0.1:8787/status" in text and "3/3" in text
    assert "failed 1, running 0" in text and "running 2" in text and "[3/3] error    b.ply: file is empty" in text
    log = io.StringIO()
    p = Progress(stream=log)
    p.begin(3, [BatchRow("c.ply", "skipped")], None)
    p.finished(ok)
    p.finished(bad)
    assert log.getvalue().splitlines() == ["[1/3] skipped  c.ply", "[2/3] ok       a.ply  100 points  3 segments  1.5 s",
                                           "[3/3] error    b.ply: file is empty"]
    quiet = io.StringIO()
    p = Progress(quiet=True, stream=quiet)
    p.begin(2, [], "http://x")
    p.finished(ok)
    p.finished(bad)
    assert quiet.getvalue().splitlines() == ["[2/2] error    b.ply: file is empty"]


# --------------------------------------------------------------------------- a running scheduler (dask CLI)


def _dask_command() -> str | None:
    here = Path(sys.executable).parent
    return shutil.which("dask", path=os.pathsep.join([str(here), os.environ.get("PATH", "")]))


@pytest.fixture
def dask_scheduler(tmp_path: Path):
    """A scheduler and one worker started with the `dask` command line, on 127.0.0.1 only; yields
    the scheduler's address and stops both."""
    dask = _dask_command()
    if dask is None:
        pytest.skip("the `dask` command line (from distributed) is not installed")
    info = tmp_path / "scheduler.json"
    src = str(Path(houghcad.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    log = open(tmp_path / "dask.log", "w")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(info)], env=env, stdout=log, stderr=log, cwd=tmp_path)]
    try:
        deadline = time.monotonic() + 60
        while not info.is_file() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert info.is_file(), (tmp_path / "dask.log").read_text()
        procs.append(subprocess.Popen([dask, "worker", "--scheduler-file", str(info), "--host", "127.0.0.1",
                                       "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                                      env=env, stdout=log, stderr=log, cwd=tmp_path))
        yield json.loads(info.read_text())["address"]
    finally:
        for proc in reversed(procs):
            proc.terminate()
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()


def test_scheduler_address_runs_on_its_workers_and_a_given_client_stays_open(dask_scheduler: str, first_run,
                                                                             clouds: Path, tmp_path: Path):
    from distributed import Client

    _, first, *_ = first_run
    assert dask_scheduler.startswith("tcp://127.0.0.1:")
    code, stdout, stderr = _run(["batch", str(clouds / "part0.ply"), str(clouds / "part1.txt"), "-o",
                                 str(tmp_path / "cli"), "--scheduler", dask_scheduler, *SEGMENT_OPTIONS])
    assert code == 0, stderr
    assert "2 clouds: 2 ok" in stdout
    # Started with --no-dashboard, it still reports its HTTP server's port as the dashboard's,
    # whose /status page is a 404: no link to it.
    assert "Dask dashboard" not in stderr and "[2/2]" in stderr, stderr
    for stem in ("part0", "part1"):
        assert _result(tmp_path / "cli" / f"{stem}_segments.json") == _result(first / f"{stem}_segments.json")
    with Client(dask_scheduler) as client:
        rows = houghcad.batch(str(clouds / "part2.ply"), tmp_path / "api", client, seed=1, merge=False)
        assert [r.status for r in rows] == ["ok"] and client.status == "running"
        assert len(client.scheduler_info()["workers"]) == 1
    assert _result(tmp_path / "api" / "part2_segments.json") == _result(first / "part2_segments.json")


# --------------------------------------------------------------------------- interrupted


def test_interrupting_leaves_whole_outputs_and_the_summary_of_the_finished_clouds(clouds: Path, tmp_path: Path):
    import signal

    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "houghcad", "batch", str(clouds), "-o", str(out), "--workers", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    for line in proc.stderr:  # one line per cloud: stop after the second
        if line.startswith("[2/6]"):
            break
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130 and stderr.endswith("houghcad: interrupted\n") and "Traceback" not in stderr, stderr
    rows, _ = _summary(out)
    assert 2 <= len(rows) < 6 and all(r["status"] in ("ok", "error") for r in rows)
    for result in out.glob("*_segments.json"):
        assert json.loads(result.read_text())["n_points"] == N_POINTS
    assert not [p for p in os.listdir(out) if p.endswith(".tmp")]
    code, stdout, _ = _run(["batch", str(clouds), "-o", str(out), "--workers", "1"])  # the re-run completes it
    rows, _ = _summary(out)
    assert code == 1 and len(rows) == 6 and all(r["n_segments"] for r in rows if r["status"] != "error")


# --------------------------------------------------------------------------- families defined in a file

FAMILY_FILE = '''
import sympy as sp
import houghcad

u, v, k, h = sp.symbols("u v k h")
houghcad.define_family("batch_paraboloid", x=u * sp.cos(v), y=u * sp.sin(v), z=k * u**2 + h,
                       params=[k, h], u_range=None, v_range=(0, 2 * sp.pi), lengths={"k": -1, "h": 1},
                       bounds={"k": (-8, 8), "h": (-1, 1)}, placement="axis")
'''


def test_a_family_file_is_loaded_on_the_workers_and_left_out_of_the_registry(tmp_path: Path):
    from houghcad.families import REGISTRY

    rng = np.random.default_rng(2)
    pts, _ = synth.sample_parametric(lambda u, v: u * np.cos(v), lambda u, v: u * np.sin(v),
                                     lambda u, v: 0.6 * u**2, (0, 1.0), (0, 2 * np.pi), 1500, rng)
    np.savetxt(tmp_path / "bowl.xyz", pts @ synth.random_rotation(rng).T * 3.0)
    (tmp_path / "fams.py").write_text(FAMILY_FILE)
    options = ["--family-file", str(tmp_path / "fams.py"), "--families", "plane,batch_paraboloid"]
    code, _, stderr = _run(["batch", str(tmp_path / "bowl.xyz"), "-o", str(tmp_path / "out"), "--workers", "1",
                            *options])
    assert code == 0, stderr
    assert "batch_paraboloid" not in REGISTRY  # checking the options did not leave it registered here
    result = _result(tmp_path / "out" / "bowl_segments.json")
    assert max(result["segments"], key=lambda s: len(s["indices"]))["type"] == "batch_paraboloid"
    try:
        assert main(["segment", str(tmp_path / "bowl.xyz"), "-o", str(tmp_path / "seg.json"), "-q", *options]) == 0
    finally:
        REGISTRY.pop("batch_paraboloid", None)
    assert result == _result(tmp_path / "seg.json")


# --------------------------------------------------------------------------- options of the Python API


@pytest.mark.parametrize("options,word", [
    ({"epsilon": 2.0}, "epsilon must be a fraction of the diagonal in (0, 0.5)"),  # the CLI's --epsilon 2 too
    ({"epsilon": "0.01"}, "epsilon must be a number"),
    ({"persistence": 1.5}, "persistence"),
    ({"bogus": 3}, "unknown option bogus"),
    ({"n_jobs": 2}, "unknown option n_jobs"),
    ({"families": ["plane", "cylinder"]}, "families must be a string"),
    ({"families": "plane,blob"}, "blob"),
    ({"tolerances": {"recognition.nonsense": 1}}, "nonsense"),
    ({"tolerances": {"recognition": {"keep_share": -1}}}, "keep_share must be positive"),
    ({"tolerances": [("recognition.keep_share", 0.5)]}, "tolerances must be a Tolerances, a dict or None"),
    ({"normals_method": "bogus"}, "unknown normals method 'bogus'"),
    ({"noise": "loud"}, "noise must be one of"),
    ({"min_points": 1}, "min_points"),
    ({"seed": -1}, "seed"),
    ({"max_points": 10}, "max_points must be a whole number of at least 1000"),
    ({"merge": "no"}, "merge must be True or False"),
    ({"timeout": -1}, "timeout must be a positive number"),
])
def test_a_bad_option_is_one_input_error_before_any_cloud_runs(clouds: Path, tmp_path: Path, options, word):
    with pytest.raises(houghcad.InputError) as caught:
        houghcad.batch(str(clouds / "part0.ply"), tmp_path / "out", workers=1, **options)
    assert word in str(caught.value) and "\n" not in str(caught.value)
    assert not (tmp_path / "out").exists()  # refused before the cluster and the output folder


def test_tolerances_given_as_a_tolerances_object_or_either_dict_are_the_same_options(tmp_path: Path):
    from houghcad.batchcheck import segment_options

    expected = (("recognition.keep_share", 0.5),)
    for given in (houghcad.Tolerances.from_dict({"recognition.keep_share": 0.5}),
                  {"recognition": {"keep_share": 0.5}}, {"recognition.keep_share": 0.5}):
        opts = segment_options({"tolerances": given})
        assert opts.tolerances == expected and opts.segment_kwargs()["tolerances"] == {"recognition.keep_share": 0.5}
    assert segment_options({"tolerances": houghcad.Tolerances()}).tolerances == ()
    (tmp_path / "fams.py").write_text("")  # one path, not a list: taken whole, not letter by letter
    assert segment_options({"family_files": str(tmp_path / "fams.py")}).family_files == (str(tmp_path / "fams.py"),)


# --------------------------------------------------------------------------- a script without the main guard


def test_in_a_worker_importing_the_main_script_batch_refuses_at_once(monkeypatch, clouds: Path, tmp_path: Path,
                                                                     capsys):
    import multiprocessing

    from houghcad.batchcheck import MARKER, UNGUARDED

    # What a worker spawned by Dask sees while it runs the parent's main script (checked with a
    # real worker: parent_process() is still None then, and __main__ not yet renamed).
    monkeypatch.setattr(multiprocessing.current_process(), "_inheriting", True, raising=False)
    monkeypatch.setattr(sys, "excepthook", sys.excepthook)  # restored after the test
    marker = tmp_path / "unguarded"
    monkeypatch.setenv(MARKER, str(marker))
    with pytest.raises(houghcad.InputError) as caught:
        houghcad.batch(str(clouds / "part0.ply"), tmp_path / "out", epsilon=2.0)  # refused before the options
    assert str(caught.value) == UNGUARDED and 'if __name__ == "__main__":' in UNGUARDED
    assert marker.is_file() and not (tmp_path / "out").exists()
    # The worker dies of it: silent when the batch that started it says it (the marker)...
    sys.excepthook(type(caught.value), caught.value, None)
    assert capsys.readouterr().err == ""
    # ...one line otherwise; and any other exception as before.
    monkeypatch.delenv(MARKER)
    with pytest.raises(houghcad.InputError) as again:
        houghcad.batch(str(clouds / "part0.ply"), tmp_path / "out")
    sys.excepthook(type(again.value), again.value, None)
    assert capsys.readouterr().err == f"houghcad: error: {UNGUARDED}\n"
    sys.excepthook(ValueError, ValueError("something else"), None)
    assert "ValueError: something else" in capsys.readouterr().err


def test_a_script_calling_batch_without_the_main_guard_fails_with_one_message(clouds: Path, tmp_path: Path):
    from houghcad.batchcheck import UNGUARDED

    script = tmp_path / "unguarded.py"  # as a user would paste the README's example, without the guard
    script.write_text(f"import houghcad\nrows = houghcad.batch({str(clouds / 'part0.ply')!r}, "
                      f"{str(tmp_path / 'out')!r}, workers=2)\nprint('rows', rows)\n")
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 1 and proc.stdout == "" and time.monotonic() - t0 < 60
    # The parent's own traceback, ending with the one line; nothing from the workers nor from Dask.
    assert proc.stderr.count("Traceback") == 1 and proc.stderr.endswith(f"houghcad.errors.InputError: {UNGUARDED}\n")
    assert "Nanny" not in proc.stderr and "RuntimeError" not in proc.stderr and "distributed" not in proc.stderr
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- workers that die


KILLER = '''
import os, signal
try:
    from distributed import get_worker

    get_worker()
except (ImportError, ValueError):  # checking the options, in the batch's own process
    pass
else:  # on a worker, for every attempt of every cloud
    os.kill(os.getpid(), signal.SIGKILL)
'''


def test_clouds_whose_workers_die_give_one_wording_and_no_dask_log_lines(clouds: Path, tmp_path: Path):
    # A cloud whose worker died twice read "worker died (exit code -9)" when its first start
    # event was lost with its worker, and the scheduler's ERROR line reached stderr under -q.
    (tmp_path / "killer.py").write_text(KILLER)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "houghcad", "batch", str(clouds / "part0.ply"), str(clouds / "part2.ply"),
                           "-o", str(out), "--workers", "2", "--retries", "1", "-q",
                           "--family-file", str(tmp_path / "killer.py")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1 and proc.stdout == ""
    died = "worker died 2 times (exit code -9) (SIGKILL: out of memory?)"
    lines = proc.stderr.splitlines()  # the two failures, in the order they ended, and nothing else
    assert [line[:6] for line in lines] == ["[1/2] ", "[2/2] "], proc.stderr
    assert sorted(line[6:] for line in lines) == [f"error    {clouds / n}: {died}" for n in ("part0.ply", "part2.ply")]
    rows, _ = _summary(out)
    assert [(r["status"], r["error"]) for r in rows] == [("error", died)] * 2


def test_a_cloud_that_left_rows_out_is_scored_in_its_file_rows(tmp_path: Path):
    # Rows 2 and 5 of the file were left out (--drop-invalid): the truth numbers the file's rows.
    from houghcad.batch import _measures
    from houghcad.result import Result, Segment

    rows = np.setdiff1d(np.arange(30), [2, 5])
    gt = tmp_path / "c_primitives.txt"
    gt.write_text("".join(f"Primitive{j + 1}:=[{' '.join(str(r + 1) for r in part)}];\n"
                          for j, part in enumerate((rows[:14], rows[14:]))))
    segs = [Segment(0, "plane", np.arange(14), {}, 0.0), Segment(1, "plane", np.arange(14, 28), {}, 0.0)]
    result = Result(28, segs, np.zeros(0, np.int64),
                    options={"input": {"rows": 30, "drop_invalid": True, "dropped_rows": [[2, 3], [5, 6]]}})
    job = CloudJob(str(tmp_path / "c.xyz"), "c.xyz", str(tmp_path), "c", ("json",), SegmentOptions(),
                   ground_truth=str(gt))
    measures, problem = _measures(job, result)
    assert problem is None and measures["DSC"] == 1.0
