"""The ``houghcad`` command line: errors, outputs, and (with the real pipeline) the happy path."""

from __future__ import annotations

import importlib.resources
import io
import json
import shutil
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from houghcad import __version__
from houghcad.cli import main
from houghcad.result import Result, Segment

# --------------------------------------------------------------------------- helpers


def _write_xyz(path: Path, pts: np.ndarray) -> Path:
    np.savetxt(path, pts, fmt="%.9f")
    return path


def _blob(n: int = 200, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n, 3))


def _parts_cloud(seed: int = 0) -> np.ndarray:
    """~3000 points: two perpendicular 10x10 planes and a radius-2 cylinder standing on one."""
    rng = np.random.default_rng(seed)
    n = 1000
    floor = np.column_stack([rng.uniform(0, 10, n), rng.uniform(0, 10, n), np.zeros(n)])
    wall = np.column_stack([np.zeros(n), rng.uniform(0, 10, n), rng.uniform(0, 10, n)])
    theta = rng.uniform(0, 2 * np.pi, n)
    cyl = np.column_stack([6 + 2 * np.cos(theta), 6 + 2 * np.sin(theta), rng.uniform(0.5, 6, n)])
    return np.vstack([floor, wall, cyl])


def _assert_one_line_error(capsys, *words: str) -> str:
    out, err = capsys.readouterr()
    assert out == ""
    lines = err.strip("\n").split("\n")
    assert len(lines) == 1, err
    assert lines[0].startswith("houghcad: error: "), err
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], err
    return lines[0]


def _fake_result(n_points: int, source: str | None = None) -> Result:
    segs = [
        Segment(0, "plane", np.arange(0, n_points // 2, dtype=np.int64),
                {"normal": [0.0, 0.0, 1.0], "offset": 0.0, "point": [0.0, 0.0, 0.0]}, 1e-3),
        Segment(1, "cylinder", np.arange(n_points // 2, n_points - 5, dtype=np.int64),
                {"axis_point": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "radius": 2.0}, 2e-3),
    ]
    return Result(n_points=n_points, segments=segs, unsegmented=np.arange(n_points - 5, n_points, dtype=np.int64),
                  timing={"preprocess": 0.1, "hough": 0.5, "total": 0.7}, options={}, source=source)


@pytest.fixture
def fake_pipeline(monkeypatch):
    """Replace ``houghcad.pipeline`` by a stub that records its calls.

    ``stub.behaviour`` may be set to an exception instance (raised by segment)
    or a callable (n_points -> Result).
    """
    stub = types.ModuleType("houghcad.pipeline")
    stub.calls = []
    stub.behaviour = None

    def segment(points, normals=None, **kwargs):
        stub.calls.append({"points": points, "normals": normals, **kwargs})
        if isinstance(stub.behaviour, BaseException):
            raise stub.behaviour
        if callable(stub.behaviour):
            return stub.behaviour(len(points))
        return _fake_result(len(points), kwargs.get("source"))

    stub.segment = segment
    monkeypatch.setitem(sys.modules, "houghcad.pipeline", stub)
    return stub


# --------------------------------------------------------------------------- basics


def test_version(capsys):
    assert main(["--version"]) == 0
    from houghcad.kernels import aot_loaded

    how = "compiled ahead of time" if aot_loaded() else "compiled by numba on first use"
    assert capsys.readouterr().out.strip() == f"houghcad {__version__} (kernels {how})"


def test_help_exits_zero(capsys):
    assert main(["segment", "--help"]) == 0
    assert "--fit4cad" in capsys.readouterr().out


def test_segment_help_names_every_readable_format(capsys):
    from houghcad.io.readers import FORMAT_TABLE

    assert main(["segment", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split()).upper()  # help lines wrap anywhere
    for f in FORMAT_TABLE:
        for ext in f.extensions or (f".{f.name}",):
            assert ext[1:].upper() in out, f.name


@pytest.mark.parametrize("argv,word", [
    ([], "required"),
    (["frobnicate"], "invalid choice"),
    (["segment"], "INPUT"),
    (["segment", "x.xyz", "--epsilon", "abc"], "--epsilon"),
    (["segment", "x.xyz", "--epsilon", "-0.1"], "--epsilon"),
    (["segment", "x.xyz", "--epsilon", "nan"], "--epsilon"),
    (["segment", "x.xyz", "--epsilon", "0.7"], "--epsilon"),
    (["segment", "x.xyz", "--seed", "-1"], "--seed"),
    (["segment", "x.xyz", "--normals", "magic"], "--normals"),
    (["segment", "x.xyz", "--bogus"], "--bogus"),
    (["evaluate", "only_one.json"], "GROUND_TRUTH"),
])
def test_usage_errors(capsys, argv, word):
    assert main(argv) == 2
    _assert_one_line_error(capsys, word)


# --------------------------------------------------------------------------- bad input files


def _bad_inputs(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """name -> (file, word expected in the message)."""
    cases: dict[str, tuple[Path, str]] = {}
    p = tmp_path / "empty.xyz"
    p.write_text("")
    cases["empty"] = (p, "empty")
    p = tmp_path / "words.xyz"
    p.write_text("1 2 3\n4 five 6\n" * 20)
    cases["non-numeric"] = (p, "non-numeric")
    pts = _blob()
    pts[5, 0] = np.nan
    cases["nan"] = (_write_xyz(tmp_path / "nan.xyz", pts), "NaN")
    pts[5, 0] = np.inf
    cases["inf"] = (_write_xyz(tmp_path / "inf.xyz", pts), "infinite")
    cases["ten"] = (_write_xyz(tmp_path / "ten.xyz", _blob(10)), "only 10 points")
    t = np.linspace(0, 1, 50)[:, None]
    cases["collinear"] = (_write_xyz(tmp_path / "line.xyz", t * [1.0, 2.0, 3.0]), "collinear")
    cases["missing"] = (tmp_path / "missing.ply", "file not found")
    p = tmp_path / "garbage.foo"
    p.write_bytes(b"\x89garbage \x00\x01 not a cloud")
    cases["unknown"] = (p, "unrecognised file format")
    return cases


@pytest.mark.parametrize("case", ["empty", "non-numeric", "nan", "inf", "ten", "collinear",
                                  "missing", "unknown"])
def test_segment_bad_input(tmp_path, capsys, monkeypatch, fake_pipeline, case):
    path, word = _bad_inputs(tmp_path)[case]
    out = tmp_path / "out" / "result.json"
    out.parent.mkdir()
    monkeypatch.chdir(tmp_path)
    before = sorted(tmp_path.rglob("*"))
    assert main(["segment", str(path), "-o", str(out), "--fit4cad", str(tmp_path / "f4c")]) == 2
    _assert_one_line_error(capsys, str(path), word)
    assert sorted(tmp_path.rglob("*")) == before  # no partial output, no directory created
    assert fake_pipeline.calls == []


def test_segment_bad_input_subprocess(tmp_path):
    bad = tmp_path / "bad.xyz"
    bad.write_text("1 2 3\nx y z w\n")
    proc = subprocess.run([sys.executable, "-m", "houghcad", "segment", "bad.xyz"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip("\n").split("\n")
    assert len(lines) == 1 and lines[0].startswith("houghcad: error: bad.xyz: "), proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.xyz"]


def test_subprocess_missing_file_and_usage(tmp_path):
    for argv, word in ((["segment", "nope.ply"], "nope.ply: file not found"), (["segment"], "INPUT")):
        proc = subprocess.run([sys.executable, "-m", "houghcad", *argv],
                              cwd=tmp_path, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2
        assert "Traceback" not in proc.stderr
        assert proc.stderr.count("\n") == 1 and word in proc.stderr


# --------------------------------------------------------------------------- output paths (stub pipeline)


def test_output_directory_missing(tmp_path, capsys, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    out = tmp_path / "no" / "such" / "r.json"
    assert main(["segment", str(inp), "-o", str(out)]) == 2
    _assert_one_line_error(capsys, str(out), "does not exist")
    assert fake_pipeline.calls == []  # failed before the (long) run


def test_output_is_a_directory(tmp_path, capsys, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    assert main(["segment", str(inp), "-o", str(tmp_path)]) == 2
    _assert_one_line_error(capsys, "is a directory")


def test_output_would_overwrite_input(tmp_path, capsys, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    before = inp.read_bytes()
    assert main(["segment", str(inp), "-o", str(inp)]) == 2
    _assert_one_line_error(capsys, "overwrite the input")
    assert inp.read_bytes() == before


def test_fit4cad_output_would_overwrite_the_ground_truth_beside_the_input(tmp_path, capsys, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    truth = tmp_path / "part_primitives.txt"
    truth.write_text("Primitive1:=[1 2 3];\n")
    assert main(["segment", str(inp), "-o", str(tmp_path / "o.json"), "--fit4cad", str(tmp_path)]) == 2
    _assert_one_line_error(capsys, "ground truth")
    assert truth.read_text() == "Primitive1:=[1 2 3];\n" and not fake_pipeline.calls


def test_trace_files_would_overwrite_the_input(tmp_path, capsys, fake_pipeline):
    trace = tmp_path / "trace"
    trace.mkdir()
    inp = _write_xyz(trace / "01_recognition.ply.xyz", _blob())  # not a trace file's name: fine
    assert main(["segment", str(inp), "-o", str(tmp_path / "a.json"), "--trace", str(trace)]) == 0
    capsys.readouterr()
    from houghcad.io import write_points_ply

    ply = trace / "01_recognition.ply"
    write_points_ply(ply, _blob())
    before = ply.read_bytes()
    assert main(["segment", str(ply), "-o", str(tmp_path / "b.json"), "--trace", str(trace)]) == 2
    _assert_one_line_error(capsys, "overwrite the input", "--trace")
    assert ply.read_bytes() == before


def test_oserror_while_writing_becomes_one_line(tmp_path, capsys, monkeypatch, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    out = tmp_path / "r.json"

    def deny(path, obj):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr("houghcad.cli.write_json", deny)
    assert main(["segment", str(inp), "-o", str(out)]) == 2
    _assert_one_line_error(capsys, str(out), "Permission denied")
    assert not out.exists()


def test_failing_run_leaves_no_output(tmp_path, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    out = tmp_path / "r.json"
    fake_pipeline.behaviour = RuntimeError("pipeline bug")
    with pytest.raises(RuntimeError, match="pipeline bug"):  # real bugs keep their traceback
        main(["segment", str(inp), "-o", str(out), "--fit4cad", str(tmp_path / "f4c")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part.xyz"]


def test_failing_serialisation_leaves_no_partial_file(tmp_path, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    out = tmp_path / "r.json"

    def unserialisable(n):
        res = _fake_result(n)
        res.options = {"callback": object()}  # json cannot encode this
        return res

    fake_pipeline.behaviour = unserialisable
    with pytest.raises(TypeError):
        main(["segment", str(inp), "-o", str(out)])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part.xyz"]


def test_bad_families_from_pipeline_is_exit_2(tmp_path, capsys, fake_pipeline):
    from houghcad.errors import InputError

    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    fake_pipeline.behaviour = InputError("unknown primitive family 'blob'")
    assert main(["segment", str(inp), "-o", str(tmp_path / "r.json"), "--families", "plane,blob"]) == 2
    _assert_one_line_error(capsys, "blob")
    assert not (tmp_path / "r.json").exists()


def test_keyboard_interrupt_says_one_line_and_exits_130(tmp_path, capsys, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    fake_pipeline.behaviour = KeyboardInterrupt()
    assert main(["segment", str(inp), "-o", str(tmp_path / "r.json")]) == 130
    assert capsys.readouterr().err == "houghcad: interrupted\n"
    assert not (tmp_path / "r.json").exists()


def test_the_command_imports_nothing_heavy_before_it_catches_a_ctrl_c():
    # A Ctrl-C in the first 0.3 s of a command, while numpy was imported, printed a traceback:
    # the entry point (and the package it sits in) imports only the standard library first.
    code = ("import sys, houghcad._console; "
            "print(sorted(m for m in ('numpy', 'scipy', 'houghcad.cli', 'houghcad.result') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == "[]", done.stdout + done.stderr


def test_a_closed_pipe_ends_quietly_with_the_outputs_written(tmp_path):
    inp = _write_xyz(tmp_path / "part.xyz", _parts_cloud())
    out = tmp_path / "r.json"
    # `houghcad segment ... | head -c 1`: the reader goes away after one byte.
    cmd = f"{sys.executable} -m houghcad segment {inp} -o {out} | head -c 1"
    done = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, timeout=300)
    assert done.stderr == "" and done.returncode == 0
    assert json.loads(out.read_text())["n_points"] == len(_parts_cloud())


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_standard_output_is_one_line_and_exit_2(tmp_path):
    inp = _write_xyz(tmp_path / "part.xyz", _parts_cloud())
    out = tmp_path / "r.json"
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "houghcad", "segment", str(inp), "-o", str(out)],
                              stdout=full, stderr=subprocess.PIPE, text=True, timeout=300)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr == "houghcad: error: cannot write to standard output (No space left on device)\n"
    assert json.loads(out.read_text())["n_points"] == len(_parts_cloud())  # the files were written first
    assert Path("/dev/full").is_char_device()


def test_segment_with_stub_writes_outputs(tmp_path, capsys, monkeypatch, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob(100))
    monkeypatch.chdir(tmp_path)
    argv = ["segment", "part.xyz", "--families", "plane,cylinder", "--epsilon", "0.02", "--seed", "3",
            "--normals", "pca", "--fit4cad", "f4c/nested"]
    assert main(argv) == 0
    (call,) = fake_pipeline.calls
    assert call["families"] == "plane,cylinder" and call["epsilon"] == 0.02
    assert call["seed"] == 3 and call["normals_method"] == "pca" and call["source"] == "part.xyz"
    assert call["points"].shape == (100, 3) and call["normals"] is None

    data = json.loads((tmp_path / "part_segments.json").read_text())  # default -o
    assert data["n_points"] == 100 and [s["type"] for s in data["segments"]] == ["plane", "cylinder"]
    prim = (tmp_path / "f4c" / "nested" / "part_primitives.txt").read_text()
    assert prim.startswith("Primitive1:=[1 2 3 ") and "\n\nPrimitive2:=[51 52 " in prim
    assert prim.endswith("95];\n\n")

    out = capsys.readouterr().out
    assert "plane" in out and "cylinder" in out and "unsegmented" in out and "wrote" in out
    assert inp.read_bytes() == _write_xyz(tmp_path / "again.xyz", _blob(100)).read_bytes()


def test_quiet_silences_warnings_for_the_command_only(tmp_path, capsys, fake_pipeline):
    import warnings

    inp = _write_xyz(tmp_path / "part.xyz", _blob())

    def warn(n):
        warnings.warn("a library's warning", RuntimeWarning)
        return _fake_result(n)

    fake_pipeline.behaviour = warn
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        assert main(["segment", str(inp), "-o", str(tmp_path / "r.json"), "-q"]) == 0
        assert not seen
        warnings.warn("the caller's own", UserWarning)  # the filter is the caller's again
        assert [str(w.message) for w in seen] == ["the caller's own"]
    assert capsys.readouterr() == ("", "")


def test_quiet_prints_nothing(tmp_path, capsys, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    assert main(["segment", str(inp), "-o", str(tmp_path / "r.json"), "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    assert (tmp_path / "r.json").is_file()


# --------------------------------------------------------------------------- demo (stub pipeline)


def test_demo_missing_data_file(tmp_path, capsys, monkeypatch, fake_pipeline):
    monkeypatch.setattr(importlib.resources, "files", lambda pkg: tmp_path / "pkg")
    monkeypatch.chdir(tmp_path)
    assert main(["demo"]) == 2
    _assert_one_line_error(capsys, "demo_part.ply", "missing")
    assert not (tmp_path / "houghcad-demo").exists()


def test_demo_with_stub(tmp_path, capsys, monkeypatch, fake_pipeline):
    data = tmp_path / "pkg" / "data"
    data.mkdir(parents=True)
    from houghcad.io import write_points_ply

    write_points_ply(data / "demo_part.ply", _blob(300))
    # The stand-in package keeps the report's script and style.
    shutil.copytree(importlib.resources.files("houghcad") / "data" / "report", data / "report")
    monkeypatch.setattr(importlib.resources, "files", lambda pkg: tmp_path / "pkg")
    monkeypatch.chdir(tmp_path)
    assert main(["demo"]) == 0
    result = json.loads((tmp_path / "houghcad-demo" / "demo_part_segments.json").read_text())
    assert result["n_points"] == 300
    assert "plane" in capsys.readouterr().out
    assert main(["demo", "-o", str(tmp_path / "elsewhere"), "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    assert (tmp_path / "elsewhere" / "demo_part_segments.json").is_file()


# --------------------------------------------------------------------------- evaluate


def _eval_files(tmp_path: Path) -> tuple[Path, Path]:
    res = _fake_result(100)
    rpath = tmp_path / "PC_segments.json"
    rpath.write_text(json.dumps(res.to_dict()))
    gt = tmp_path / "PC_primitives.txt"
    gt.write_text("Primitive1:=[" + " ".join(str(i) for i in range(1, 51)) + "];\n\n"
                  "Primitive2:=[" + " ".join(str(i) for i in range(51, 101)) + "];\n\n")
    return rpath, gt


def test_evaluate_text_and_json(tmp_path, capsys):
    rpath, gt = _eval_files(tmp_path)
    assert main(["evaluate", str(rpath), str(gt)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("DSC")
    assert any(line.startswith("MFE") for line in out)
    assert main(["evaluate", str(rpath), str(gt), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert list(report["measures"])[0] == "DSC"
    assert report["measures"]["DSC"] == pytest.approx(1.0 - (5 / 2) / 100, abs=0.05)
    assert report["n_gt"] == 2 and report["n_pred"] == 2 and report["scored"] == "faces"
    assert set(report["mfe"]) == {"min", "mean", "max"}
    assert main(["evaluate", str(rpath), str(gt), "--maximal", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["scored"] == "maximal"
    assert main(["evaluate", str(rpath), str(gt), "--maximal"]) == 0
    assert "predicted maximal primitives (ratio" in capsys.readouterr().out


def test_evaluate_missing_files(tmp_path, capsys):
    rpath, gt = _eval_files(tmp_path)
    assert main(["evaluate", str(tmp_path / "nope.json"), str(gt)]) == 2
    _assert_one_line_error(capsys, "nope.json")
    assert main(["evaluate", str(rpath), str(tmp_path / "nope_primitives.txt")]) == 2
    _assert_one_line_error(capsys, "nope_primitives.txt")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert main(["evaluate", str(bad), str(gt)]) == 2
    _assert_one_line_error(capsys, "bad.json")


# --------------------------------------------------------------------------- happy path (real pipeline)


def test_segment_real_pipeline(tmp_path, capsys):
    pts = _parts_cloud()
    inp = _write_xyz(tmp_path / "parts.xyz", pts)
    before = (inp.read_bytes(), inp.stat().st_mtime_ns)
    out = tmp_path / "parts.json"
    assert main(["segment", str(inp), "-o", str(out), "--fit4cad", str(tmp_path / "f4c")]) == 0
    assert (inp.read_bytes(), inp.stat().st_mtime_ns) == before

    data = json.loads(out.read_text())
    assert data["n_points"] == len(pts)
    assert isinstance(data["segments"], list) and data["segments"]
    for seg in data["segments"]:
        assert {"type", "indices", "params", "mfe"} <= set(seg)
        assert seg["type"] in {"plane", "cylinder", "cone", "sphere", "torus"}
        idx = np.asarray(seg["indices"])
        assert idx.size and idx.min() >= 0 and idx.max() < len(pts)
        assert isinstance(seg["params"], dict)
    assert "plane" in {s["type"] for s in data["segments"]}
    assert isinstance(data["unsegmented"], list)
    assert isinstance(data["timing"], dict)
    # The indices are the file's rows, none left out (options.input, docs/schema.md).
    assert data["options"]["input"] == {"rows": len(pts), "scan": None, "drop_invalid": False, "dropped_rows": [],
                                        "dropped": {"flagged_invalid": 0, "non_finite": 0}}

    prim = (tmp_path / "f4c" / "parts_primitives.txt").read_text()
    # One block per face: a maximal primitive contributes one block per part.
    assert prim.count("Primitive") == sum(max(1, len(s.get("parts", []))) for s in data["segments"])
    table = capsys.readouterr().out
    assert "plane" in table and "unsegmented" in table and "scales" in table


def test_segment_trace_writes_the_labels_after_every_pass(tmp_path):
    from plyfile import PlyData

    pts = _parts_cloud()
    inp = _write_xyz(tmp_path / "parts.xyz", pts)
    out = tmp_path / "parts.json"
    trace = tmp_path / "trace"
    assert main(["segment", str(inp), "-o", str(out), "--trace", str(trace), "-q"]) == 0
    files = sorted(p.name for p in trace.iterdir())
    assert files[0] == "01_recognition.ply" and files[-1].endswith("_association.ply")
    assert [int(f[:2]) for f in files] == list(range(1, len(files) + 1))
    data = json.loads(out.read_text())
    assert set(data["timing"]) >= {f[3:-4] for f in files}
    last = PlyData.read(str(trace / files[-1]))
    assert "houghcad pass association" in last.comments
    lab = np.asarray(last["vertex"]["segment"])
    assert len(lab) == len(pts)
    # The last trace is the result's partition (ids are numbered by size in the result).
    mine = sorted(np.bincount(lab[lab >= 0]).tolist())
    assert mine == sorted(len(s["indices"]) for s in data["segments"])
    np.testing.assert_array_equal(np.flatnonzero(lab < 0), data["unsegmented"])

    # A subsampled run (it raised after the whole run, and wrote no result): the trace holds
    # the subsample the passes ran on, each point with its input row.
    sub = tmp_path / "sub"
    assert main(["segment", str(inp), "-o", str(tmp_path / "sub.json"), "--trace", str(sub),
                 "--max-points", "1000", "-q"]) == 0
    v = PlyData.read(str(sorted(sub.iterdir())[-1]))["vertex"].data
    rows = np.asarray(v["input_index"])
    assert len(rows) <= 1000 < len(pts) and (tmp_path / "sub.json").is_file()
    np.testing.assert_allclose(np.c_[v["x"], v["y"], v["z"]], pts[rows], atol=1e-8)  # the file: 9 decimals


def test_segment_passes_noise_persistence_min_points_and_tolerances(tmp_path, fake_pipeline):
    inp = _write_xyz(tmp_path / "parts.xyz", _parts_cloud())
    assert main(["segment", str(inp), "-o", str(tmp_path / "o.json"), "-q", "--noise", "noisy",
                 "--persistence", "0.2", "--min-points", "25", "--tolerance", "recognition.keep_share=0.5",
                 "--tolerance", "splitting.max_rounds=3"]) == 0
    call = fake_pipeline.calls[-1]
    assert call["noise"] == "noisy" and call["persistence"] == 0.2 and call["min_points"] == 25
    assert call["tolerances"] == {"recognition.keep_share": 0.5, "splitting.max_rounds": 3.0}
    assert call["n_jobs"] is None  # every core unless told


def test_segment_jobs_reaches_the_pipeline(tmp_path, fake_pipeline):
    inp = _write_xyz(tmp_path / "parts.xyz", _parts_cloud())
    assert main(["segment", str(inp), "-o", str(tmp_path / "o.json"), "-q", "--jobs", "2"]) == 0
    assert fake_pipeline.calls[-1]["n_jobs"] == 2


@pytest.mark.parametrize("argv, message", [
    (["--tolerance", "recognition.keep=1"], "unknown tolerance recognition.keep"),
    (["--tolerance", "recognition.keep_share"], "expected STAGE.NAME=VALUE"),
    (["--tolerance", "splitting.max_rounds=2.5"], "whole number"),
    (["--persistence", "1.5"], "not in (0, 1)"),
    (["--min-points", "1"], "must be >= 2"),
    (["--min-points", "-5"], "must be >= 2"),  # not ">= 0", as the check for a seed said
    (["--jobs", "0"], "must be >= 1"),
    (["--jobs", "-5"], "must be >= 1"),
    (["--tolerance", "scale.max_radius=0"], "must be positive"),
    (["--noise", "loud"], "invalid choice"),
])
def test_segment_bad_tuning_options_exit_2_with_one_line(tmp_path, capsys, fake_pipeline, argv, message):
    inp = _write_xyz(tmp_path / "parts.xyz", _parts_cloud())
    assert main(["segment", str(inp), "-o", str(tmp_path / "o.json")] + argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not fake_pipeline.calls and not (tmp_path / "o.json").exists()


def test_segment_trace_on_a_file_is_refused(tmp_path, capsys, fake_pipeline):
    inp = _write_xyz(tmp_path / "parts.xyz", _parts_cloud())
    (tmp_path / "afile").write_text("x")
    assert main(["segment", str(inp), "-o", str(tmp_path / "o.json"), "--trace", str(tmp_path / "afile")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--trace needs a directory" in err
    assert not (tmp_path / "o.json").exists()


def test_segment_ply_keeps_the_input_fields_and_adds_normals_and_distances(tmp_path):
    from plyfile import PlyData

    from houghcad import synth
    from houghcad.io import write_points_ply

    cloud = synth.block_with_hole_and_slot(seed=1, n_points=3000, noise=0.002)
    n = len(cloud.points)
    inp = tmp_path / "in.ply"
    intensity = (np.arange(n) * 7) % 250
    write_points_ply(inp, cloud.points, fields={"intensity": intensity, "segment": np.ones(n)},
                     colors=np.full((n, 3), 100))
    assert main(["segment", str(inp), "-o", str(tmp_path / "r.json"), "--ply", str(tmp_path / "o.ply"), "-q"]) == 0
    v = PlyData.read(str(tmp_path / "o.ply"))["vertex"].data
    np.testing.assert_array_equal(v["intensity"], intensity)  # the input's own fields, kept
    assert (v["input_segment"] == 1).all() and (v["input_red"] == 100).all()  # renamed where ours collide
    data = json.loads((tmp_path / "r.json").read_text())
    lab = np.asarray(v["segment"])
    normals = np.column_stack([v["nx"], v["ny"], v["nz"]])
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    assert np.isnan(v["distance"][lab < 0]).all() and np.isfinite(v["distance"][lab >= 0]).all()
    sigma = data["options"]["derived"]["sigma"]
    np.testing.assert_allclose(v["distance_sigma"][lab >= 0], v["distance"][lab >= 0] / sigma, rtol=1e-4)
    # Noise-aware: the points lie within a few σ of their surfaces.
    assert 0.3 < np.median(v["distance_sigma"][lab >= 0]) < 2.0


def test_segment_ply_keeps_the_input_field_types_and_survives_being_read_again(tmp_path):
    from plyfile import PlyData

    from houghcad import synth
    from houghcad.io import write_points_ply

    cloud = synth.block_with_hole_and_slot(seed=1, n_points=3000)
    n = len(cloud.points)
    k = np.arange(n)
    fields = {"big": (4_000_000_000 - k).astype(np.uint32), "time": 1e9 + 1e-3 * k, "flag": (k % 2).astype(np.uint8)}
    inp = tmp_path / "in.ply"
    write_points_ply(inp, cloud.points, fields=fields, colors=np.full((n, 3), 7))
    first, second = tmp_path / "o.ply", tmp_path / "o2.ply"
    assert main(["segment", str(inp), "-o", str(tmp_path / "r.json"), "--ply", str(first), "-q"]) == 0
    v = PlyData.read(str(first))["vertex"].data
    for name, values in fields.items():  # a u4 stayed u4, an f8 f8: no value changed
        assert v[name].dtype == values.dtype.newbyteorder("<") or v[name].dtype == values.dtype
        np.testing.assert_array_equal(v[name], values)
    assert (v["input_red"] == 7).all()
    # houghcad's own PLY as an input: its "red" is renamed past the "input_red" it already holds.
    assert main(["segment", str(first), "-o", str(tmp_path / "r2.json"), "--ply", str(second), "-q"]) == 0
    w = PlyData.read(str(second))["vertex"].data
    assert (w["input_red"] == 7).all()
    np.testing.assert_array_equal(w["input_input_red"], v["red"])
    np.testing.assert_array_equal(w["input_segment"], v["segment"])


def test_demo_real(tmp_path, capsys):
    assert main(["demo", "-o", str(tmp_path / "demo"), "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    data = json.loads((tmp_path / "demo" / "demo_part_segments.json").read_text())
    assert data["n_points"] > 0 and data["segments"]
    for name in ("demo_part_segments.ply", "demo_part_segments.png", "demo_part_report.html"):
        assert (tmp_path / "demo" / name).stat().st_size > 1000


# --------------------------------------------------------------------------- report


def test_summary_table_layout():
    from houghcad.report import summary_table

    res = _fake_result(100)
    res.segments.append(Segment(2, "plane", np.arange(95, 97, dtype=np.int64), {}, float("nan")))
    lines = summary_table(res).splitlines()
    assert lines[0].split() == ["family", "segments", "points", "mean", "MFE", "max", "MFE"]
    rows = {line.split()[0]: line.split() for line in lines[2:] if line and not line.startswith(("-", " "))}
    assert rows["plane"][1:3] == ["2", "52"] and rows["plane"][3] == "1.00e-03"  # NaN MFE ignored
    assert rows["cylinder"][1:3] == ["1", "45"]
    assert rows["total"][1:3] == ["3", "97"]
    assert rows["unsegmented"][1] == "5"
    assert rows["time"][1] == "0.70"  # the pipeline's own total wins over the sum of stages
    assert list(rows).index("plane") < list(rows).index("cylinder")
    assert len({len(line) for line in lines[:2]}) == 1
    # A long family name widens the first column: the numbers stay under their headings.
    res.segments[1].type = "generalized_cylinder"
    lines = summary_table(res).splitlines()
    ends = {len(line) for line in lines[:lines.index("-" * len(lines[0]), 2)] if line and line[0] != "-"}
    assert lines[0].index("segments") > len("generalized_cylinder") and len(ends) == 1, lines


# --------------------------------------------------------------------------- pictures, PLY, report, progress (stub pipeline)


def _grouped_result(n_points: int, source: str | None = None) -> Result:
    from houghcad.result import Group

    res = _fake_result(n_points, source)
    res.groups = [Group("translation", [0, 1], {"radius": 2.0, "offset": [1.0, 0.0, 0.0]})]
    return res


def test_segment_writes_ply_png_report(tmp_path, capsys, fake_pipeline):
    from plyfile import PlyData

    from houghcad.io import read_points
    from houghcad.palette import point_colors

    inp = _write_xyz(tmp_path / "part.xyz", _blob(300))
    fake_pipeline.behaviour = _grouped_result
    paths = {ext: tmp_path / f"out.{ext}" for ext in ("ply", "png", "html")}
    argv = ["segment", str(inp), "-o", str(tmp_path / "r.json"), "--ply", str(paths["ply"]),
            "--png", str(paths["png"]), "--report", str(paths["html"])]
    assert main(argv) == 0
    out = capsys.readouterr().out
    for p in paths.values():
        assert f"wrote {p}" in out
    assert "translation" in out and "repeated by translation" in out  # the groups follow the family table
    res = _grouped_result(300)
    v = PlyData.read(str(paths["ply"]))["vertex"].data
    np.testing.assert_array_equal(v["segment"], res.labels())
    np.testing.assert_array_equal(v["group"], res.group_labels())
    assert set(v["group"]) == {0, -1}
    pts = read_points(inp).points
    np.testing.assert_array_equal(np.column_stack([v["red"], v["green"], v["blue"]]), point_colors(res, "segment", pts))
    assert paths["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    html = paths["html"].read_text()
    assert html.count('<tr data-segment-id="') == 2 and html.count('<tr data-group-id="') == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.html", "out.ply", "out.png", "part.xyz", "r.json"]


@pytest.mark.parametrize("flag", ["--ply", "--png", "--report"])
def test_view_output_errors(tmp_path, capsys, fake_pipeline, flag):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    (tmp_path / "afile").write_text("x")
    out = tmp_path / "r.json"
    cases = [
        (tmp_path / "missing" / "v.out", ["does not exist"]),
        (tmp_path, ["is a directory"]),
        (tmp_path / "afile" / "v.out", ["not a directory"]),
        (inp, ["overwrite the input"]),
        (out, [flag, "same file as another output"]),
    ]
    for path, words in cases:
        assert main(["segment", str(inp), "-o", str(out), flag, str(path)]) == 2
        _assert_one_line_error(capsys, *words)
    assert fake_pipeline.calls == []  # every check happens before the run
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "part.xyz"]


def test_view_writer_oserror_is_one_line(tmp_path, capsys, monkeypatch, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())

    def deny(path, points, result):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr("houghcad.render.render_png", deny)
    assert main(["segment", str(inp), "-o", str(tmp_path / "r.json"), "--png", str(tmp_path / "v.png")]) == 2
    out, err = capsys.readouterr()
    # The result was written before the picture failed, and the output says so; stderr has one line.
    assert f"wrote {tmp_path / 'r.json'}" in out and "v.png" not in out
    assert err.count("\n") == 1 and err.startswith("houghcad: error: ") and "v.png" in err
    assert "Permission denied" in err and "Traceback" not in err
    assert not (tmp_path / "v.png").exists()


def test_outputs_are_announced_as_they_land(tmp_path, capsys, monkeypatch, fake_pipeline):
    """The summary comes with the result file; each picture's line follows as soon as it is
    written, before the next one starts (a big cloud's take seconds each)."""
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    seen = []

    def draw(path, points, result):
        seen.append(capsys.readouterr().out)  # what the user has read when the picture starts
        Path(path).write_bytes(b"png")

    monkeypatch.setattr("houghcad.render.render_png", draw)
    ply, png = tmp_path / "v.ply", tmp_path / "v.png"
    assert main(["segment", str(inp), "-o", str(tmp_path / "r.json"), "--ply", str(ply), "--png", str(png)]) == 0
    assert f"wrote {tmp_path / 'r.json'}" in seen[0] and f"wrote {ply}" in seen[0] and "png" not in seen[0]
    assert capsys.readouterr().out.strip() == f"wrote {png}"


def test_no_merge_reaches_a_pipeline_that_merges(tmp_path, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    seen = []

    def segment(points, normals=None, *, merge: bool = True, **kwargs):
        seen.append(merge)
        return _fake_result(len(points))

    fake_pipeline.segment = segment
    assert main(["segment", str(inp), "-o", str(tmp_path / "a.json"), "-q"]) == 0
    assert main(["segment", str(inp), "-o", str(tmp_path / "b.json"), "-q", "--no-merge"]) == 0
    assert seen == [True, False]


class _TTY(io.StringIO):
    def isatty(self) -> bool:
        return True


def _progress_stub(fake_pipeline):
    def segment(points, normals=None, progress=None, **kwargs):
        for stage, frac in (("preprocess", 0.0), ("recognition", 0.1), ("splitting", 0.6), ("done", 1.0)):
            if progress is not None:
                progress(stage, frac)
        return _fake_result(len(points))

    fake_pipeline.segment = segment


def test_progress_bar_on_a_terminal_only(tmp_path, monkeypatch, capsys, fake_pipeline):
    inp = _write_xyz(tmp_path / "part.xyz", _blob())
    _progress_stub(fake_pipeline)
    tty = _TTY()
    monkeypatch.setattr(sys, "stderr", tty)
    assert main(["segment", str(inp), "-o", str(tmp_path / "a.json")]) == 0
    drawn = tty.getvalue()
    assert "splitting" in drawn and "100%" in drawn

    quiet = _TTY()
    monkeypatch.setattr(sys, "stderr", quiet)
    assert main(["segment", str(inp), "-o", str(tmp_path / "b.json"), "--quiet"]) == 0
    assert quiet.getvalue() == ""

    monkeypatch.undo()  # back to pytest's captured (non-TTY) stderr
    _progress_stub(fake_pipeline)
    assert main(["segment", str(inp), "-o", str(tmp_path / "c.json")]) == 0
    assert capsys.readouterr().err == ""


def test_demo_writes_every_view(tmp_path, capsys, monkeypatch, fake_pipeline):
    data = tmp_path / "pkg" / "data"
    data.mkdir(parents=True)
    from houghcad.io import write_points_ply

    write_points_ply(data / "demo_part.ply", _blob(300))
    # The stand-in package keeps the report's script and style.
    shutil.copytree(importlib.resources.files("houghcad") / "data" / "report", data / "report")
    monkeypatch.setattr(importlib.resources, "files", lambda pkg: tmp_path / "pkg")
    assert main(["demo", "-o", str(tmp_path / "d")]) == 0
    names = sorted(p.name for p in (tmp_path / "d").iterdir())
    assert names == ["demo_part_report.html", "demo_part_segments.json", "demo_part_segments.ply",
                     "demo_part_segments.png"]
    out = capsys.readouterr().out
    assert all(f"wrote {tmp_path / 'd' / n}" in out for n in names)


def test_group_sentences_say_what_the_members_share():
    from houghcad.report import group_sentence
    from houghcad.result import Group

    res = _fake_result(100)
    kinds = [s.type for s in res.segments]
    res.segments[0].type = res.segments[1].type = "plane"
    # A plane's size: its two lengths in the plane (the first of its extent runs across it).
    assert group_sentence(Group("reflection", [0, 1], {"extent": [1e-15, 2.0, 0.5]}), res) == \
        "2 planes of equal size 2 × 0.5, mirrored across a plane"
    res.segments[0].type = res.segments[1].type = "cone"
    assert group_sentence(Group("rotation", [0, 1], {"half_angle": np.pi / 6}), res) == \
        "2 cones of equal half-angle 30°, repeated by rotation"
    res.segments[0].type = res.segments[1].type = "torus"
    assert group_sentence(Group("translation", [0, 1], {"major_radius": 3.0, "minor_radius": 0.5}), res) == \
        "2 tori of equal radii 3 and 0.5, repeated by translation"
    res.segments[0].type = res.segments[1].type = "plane"
    assert group_sentence(Group("same_primitive", [0], {"parts": 3}), res) == "one plane in 3 separate parts"
    assert group_sentence(Group("parallel", [0, 1], {"normal": [0, 0, 1.0]}), res) == "2 planes with parallel normals"
    res.segments[1].type = "torus"
    assert group_sentence(Group("coaxial", [0, 1], {}), res) == "2 segments on one axis"
    del kinds


def test_groups_table():
    from houghcad.report import groups_table, summary_table
    from houghcad.result import Group

    res = _fake_result(100)
    assert groups_table(res) == "" and "kind" not in summary_table(res)
    for s in res.segments:
        s.type = "cylinder"
    res.groups = [Group("parallel", [0, 1], {"axis": [0.0, 0.0, 1.0]}),
                  Group("translation", [0, 1], {"offset": [2.0, 0.0, 0.0], "radius": 0.123456})]
    lines = groups_table(res).splitlines()
    assert lines[0].split() == ["group", "kind", "members", "what"]
    assert lines[2].split()[:2] == ["1", "translation"]  # kinds in GROUP_KINDS order
    assert lines[2].endswith("2 cylinders of equal radius 0.1235, repeated by translation")
    assert lines[3].split()[:4] == ["0", "parallel", "0,", "1"] and lines[3].endswith("2 cylinders with parallel axes")
    table = summary_table(res)
    assert table.index("unsegmented") < table.index("translation") < table.index("time")


def test_the_command_skips_the_final_garbage_collection(monkeypatch):
    """`houghcad` (cli.run) returns main's exit code and freezes the collected objects, so the
    interpreter's exit does not walk them; main itself, called in long-lived processes, does not."""
    import gc

    from houghcad import cli

    monkeypatch.setattr(cli, "main", lambda argv=None: 2)
    before = gc.get_freeze_count()
    try:
        assert cli.run() == 2
        assert gc.get_freeze_count() > before
    finally:
        gc.unfreeze()


def test_a_run_loads_no_library_it_does_not_use():
    """Every run pays its imports before it reads a point: the optimiser (only the annulus's and
    the thread's final fits use it), plotting, Dask and scikit-learn stay out of a plain
    segmentation, in a fresh process as the command runs."""
    code = ("import sys, numpy as np, houghcad.cli\n"
            "from houghcad import synth\n"
            "from houghcad.pipeline import segment\n"
            "segment(synth.block_with_hole_and_slot(seed=0, n_points=3000).points)\n"
            "print(' '.join(m for m in ('scipy.optimize', 'matplotlib', 'dask', 'sklearn') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_a_coarse_float32_cloud_warns_in_one_line(tmp_path, capsys):
    """A georeferenced part saved as float32 (a scan's PLY): the run warns, in one line."""
    from plyfile import PlyData, PlyElement

    from houghcad.synth import block_with_hole_and_slot

    P = block_with_hole_and_slot(seed=0, n_points=1500).points + [3e6, 3e6, 0.0]
    v = np.empty(len(P), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    v["x"], v["y"], v["z"] = P.T
    inp = tmp_path / "geo.ply"
    PlyData([PlyElement.describe(v, "vertex")]).write(str(inp))
    fast = ["--families", "plane", "--jobs", "1"]  # the warning comes before recognition
    assert main(["segment", str(inp), "-o", str(tmp_path / "geo.json"), *fast]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("houghcad: warning:")]
    assert len(err) == 1 and "float32 values rounded to 0.25 units" in err[0]
    assert main(["segment", str(inp), "-o", str(tmp_path / "geo.json"), "-q", *fast]) == 0
    assert capsys.readouterr() == ("", "")
