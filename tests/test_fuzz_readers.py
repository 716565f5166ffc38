"""Fuzzed readers (property-based, hypothesis).

Every reader is fed mutated copies of small valid files of every format: truncated, with flipped
bytes, inserted garbage, deleted or repeated runs, inflated header counts (PLY ``element vertex
N``, OFF counts, binary STL triangle count, NPY shape, PTS count line), NaN / inf / 1e999 / huge
tokens in the text, special floats in the binary bodies, a binary body behind an ascii PLY header
and the reverse, splices of two formats, blank files.

The property: :func:`houghcad.io.read_points` either returns a valid cloud (finite (N, 3) float64
points, N >= MIN_POINTS, normals None or unit (N, 3)) or raises :class:`InputError` with one line
``"<path>: <problem>"``; anything else (another exception, a warning, a hang) is a bug. The CLI on
the same inputs ends with 0 or 2, and on 2 with one stderr line and no output file.

Deterministic (``derandomize=True``, no example database): CI sees the same inputs every run.
``HOUGHCAD_FUZZ_SCALE=10`` multiplies the example counts for a longer local run.
"""

from __future__ import annotations

import collections
import contextlib
import io
import itertools
import os
import re
import shutil
import signal
import struct
import sys
import tempfile
import threading
import time
import tracemalloc
import types
import warnings
from datetime import timedelta
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from plyfile import PlyData, PlyElement

from houghcad.cli import main
from houghcad.errors import InputError, InputWarning
from houghcad.io import read_points, write_points_ply
from houghcad.io.readers import FORMATS, MIN_POINTS
from houghcad.result import Result, Segment

from _scanner_files import e57_bytes, las_bytes, pcd_bytes

#: Multiplies every example count (``HOUGHCAD_FUZZ_SCALE=10`` for a long local run).
SCALE = float(os.environ.get("HOUGHCAD_FUZZ_SCALE", "1"))
#: Examples per test; their sum is the number of generated inputs per run (>= 2,000).
EXAMPLES = {
    "mutated": 1100,
    "forced_format": 400,
    "random_bytes": 200,
    "ply_schemas": 250,
    "npy_schemas": 200,
    "cli": 150,
}
#: A reader that does not return within this many seconds hangs (the SIGALRM guard below).
HANG_SECONDS = 10.0


def _fuzz_settings(name: str, deadline_ms: int) -> settings:
    return settings(
        max_examples=max(1, int(EXAMPLES[name] * SCALE)),
        derandomize=True,  # the same inputs on every run: CI stays deterministic
        database=None,  # no example database: derandomized runs replay nothing
        deadline=timedelta(milliseconds=deadline_ms),  # a slow example fails, a stuck one too (guard)
        print_blob=False,
    )


# --------------------------------------------------------------------------- seed corpus


def _cloud(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-5.0, 5.0, size=(n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return pts, nrm


def _rows(*columns: np.ndarray, sep: str = " ") -> list[str]:
    return [sep.join(repr(float(v)) for v in row) for row in np.hstack(columns)]


def _text(lines: list[str]) -> bytes:
    return ("\n".join(lines) + "\n").encode()


def _ply_bytes(pts, nrm, *, text: bool, byte_order: str = "<", faces: bool = False) -> bytes:
    fields = [("x", "f8"), ("y", "f8"), ("z", "f8")]
    if nrm is not None:
        fields += [("nx", "f4"), ("ny", "f4"), ("nz", "f4")]
    v = np.empty(len(pts), dtype=fields)
    v["x"], v["y"], v["z"] = pts.T
    if nrm is not None:
        v["nx"], v["ny"], v["nz"] = nrm.T
    elements = [PlyElement.describe(v, "vertex")]
    if faces:
        f = np.empty(len(pts) // 3, dtype=[("vertex_indices", "i4", (3,))])
        f["vertex_indices"] = np.arange(len(f) * 3).reshape(-1, 3)
        elements.append(PlyElement.describe(f, "face"))
    buf = io.BytesIO()
    PlyData(elements, text=text, byte_order=byte_order).write(buf)
    return buf.getvalue()


def _npy_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return buf.getvalue()


def _stl_ascii(pts: np.ndarray) -> bytes:
    lines = ["solid fuzz"]
    for tri in pts.reshape(-1, 3, 3):
        lines += ["  facet normal 0 0 1", "    outer loop"]
        lines += [f"      vertex {x!r} {y!r} {z!r}" for x, y, z in tri.tolist()]
        lines += ["    endloop", "  endfacet"]
    return _text(lines + ["endsolid fuzz"])


def _stl_binary(pts: np.ndarray) -> bytes:
    tris = pts.reshape(-1, 3, 3).astype("<f4")
    rec = np.zeros(len(tris), dtype=[("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
    rec["vertices"] = tris
    return b"fuzz binary stl".ljust(80, b" ") + struct.pack("<I", len(tris)) + rec.tobytes()


def _houghcad_ply(pts, nrm, *, binary: bool) -> bytes:
    """A PLY as houghcad's own writer makes it (normals and an intensity as extra fields)."""
    fields = {"nx": nrm[:, 0], "ny": nrm[:, 1], "nz": nrm[:, 2], "intensity": np.arange(len(pts)) % 7}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "seed.ply"
        write_points_ply(path, pts, fields=fields, binary=binary, comments=["fuzz seed"])
        return path.read_bytes()


def _pcd_columns(pts: np.ndarray, nrm: np.ndarray) -> dict[str, np.ndarray]:
    names = ("x", "y", "z", "normal_x", "normal_y", "normal_z")
    return dict(zip(names, np.hstack([pts, nrm]).T))


@cache
def seeds() -> dict[str, tuple[str, bytes]]:
    """Seed name -> (extension, bytes): small valid files of every format (30 to 120 points)."""
    p30, n30 = _cloud(30, 1)
    p45, n45 = _cloud(45, 2)
    p60, n60 = _cloud(60, 3)
    p120, _ = _cloud(120, 4)
    structured = np.empty(45, dtype=[(k, "<f8") for k in ("x", "y", "z", "nx", "ny", "nz")])
    for i, k in enumerate("xyz"):
        structured[k], structured["n" + k] = p45[:, i], n45[:, i]
    obj = [f"v {x!r} {y!r} {z!r}" for x, y, z in p45.tolist()]
    obj += [f"vn {x!r} {y!r} {z!r}" for x, y, z in n45.tolist()]
    obj += [f"f {i + 1} {i + 2} {i + 3}" for i in range(0, 45, 3)]
    return {
        "ply_ascii": (".ply", _houghcad_ply(p30, n30, binary=False)),
        "ply_binary": (".ply", _houghcad_ply(p60, n60, binary=True)),
        "ply_binary_be_faces": (".ply", _ply_bytes(p45, None, text=False, byte_order=">", faces=True)),
        "ply_ascii_faces": (".ply", _ply_bytes(p30, n30, text=True, faces=True)),
        "npy_f8": (".npy", _npy_bytes(p60)),
        "npy_f4_normals": (".npy", _npy_bytes(np.hstack([p30, n30]).astype(np.float32))),
        "npy_structured": (".npy", _npy_bytes(structured)),
        "npy_int_fortran": (".npy", _npy_bytes(np.asfortranarray((p30 * 100).astype(np.int32)))),
        "xyz": (".xyz", _text(_rows(p60))),
        "csv_header_normals": (".csv", _text(["X,Y,Z,Nx,Ny,Nz"] + _rows(p30, n30, sep=","))),
        "pts_count": (".pts", _text([str(len(p45))] + _rows(p45, np.arange(45.0)[:, None]))),
        "txt_semicolon": (".txt", _text(_rows(p30, sep=";"))),
        "asc_comment_header": (".asc", _text(["# x y z nx ny nz"] + _rows(p45, n45))),
        "fit4cad": (".txt", ("Points:=[\n" + ",\n".join(f"[{x!r}, {y!r}, {z!r}]" for x, y, z in p30.tolist())
                             + "\n];\n").encode()),
        "obj": (".obj", _text(obj)),
        "off": (".off", _text(["OFF", f"{len(p30)} 10 0"] + _rows(p30)
                              + [f"3 {i} {i + 1} {i + 2}" for i in range(0, 30, 3)])),
        "noff": (".off", _text(["NOFF 45 0 0"] + _rows(p45, n45))),
        "stl_ascii": (".stl", _stl_ascii(p45)),
        "stl_binary": (".stl", _stl_binary(p120)),
        "las": (".las", las_bytes(p45, n45, np.arange(45, dtype=np.uint16))),
        "laz": (".laz", las_bytes(p60, n60, np.arange(60, dtype=np.uint16), compressed=True)),
        "pcd_ascii": (".pcd", pcd_bytes(_pcd_columns(p30, n30), "ascii")),
        "pcd_binary": (".pcd", pcd_bytes(_pcd_columns(p45, n45), "binary")),
        "pcd_binary_compressed": (".pcd", pcd_bytes(_pcd_columns(p60, n60), "binary_compressed")),
        "e57": (".e57", e57_bytes([(p45, np.zeros(3))], intensity=False)),
    }


SEED_NAMES = tuple(seeds())
BINARY_SEEDS = frozenset({"ply_binary", "ply_binary_be_faces", "npy_f8", "npy_f4_normals", "npy_structured",
                          "npy_int_fortran", "stl_binary", "las", "laz", "pcd_binary",
                          "pcd_binary_compressed", "e57"})


# --------------------------------------------------------------------------- mutations

#: Replacements for one number of a text file.
WEIRD_NUMBERS = (b"nan", b"NaN", b"-nan", b"inf", b"-inf", b"Infinity", b"1e999", b"-1e999", b"1e308",
                 b"1.7976931348623157e308", b"-1.7e308", b"4.9e-324", b"1e-999", b"1e200", b"-0", b"0",
                 b"9" * 400, b"1" * 5000, b"0x1p3", b"1_0", b"", b"nan(123)", b"+", b".", b"e5", b"1e",
                 b"\xd9\xa1", b"\xef\xbc\x91", b"1,5", b"--1")
#: Header counts: just above the truth, around int32/uint32/int64 limits, absurd and negative.
COUNTS = (0, 1, 19, 20, 2 ** 31 - 1, 2 ** 31, 2 ** 32 - 1, 2 ** 32, 10 ** 9, 10 ** 12, 2 ** 63 - 1,
          2 ** 63, 2 ** 64, 10 ** 30, -1, -(2 ** 31), -(10 ** 12))
#: Fragments for inserted text garbage.
GARBAGE_TOKENS = ("nan", "inf", "1e999", "-", "\n", "\r", "\r\n", "\x00", ",", ";", "#", "//", "[", "]", "];",
                  "element vertex 99999", "property float x", "property list uchar int v", "end_header",
                  "format ascii 1.0", "format binary_big_endian 1.0", "ply", "OFF", "NOFF", "v", "vn",
                  "solid", "facet", "vertex", "Points:=[", " ", "\t", "\ufeff", "\u2028", "\x85", "\x0c",
                  "\xff", "é", "1", "2.5", "-3e-3", "x y z", "nx ny nz", "42")
#: Floats written into binary bodies.
SPECIAL_FLOATS = (float("nan"), float("inf"), float("-inf"), 1e308, -1e308, 3e38, 5e-324, -0.0, 1e200, 1e-200)
#: Blank files.
BLANKS = (b"", b" ", b"\n\n", b"\t \r\n", b"\xef\xbb\xbf", b"\xef\xbb\xbf \n", b"\x00", b"\x00" * 100)

_NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_PLY_ELEMENT = re.compile(rb"element (\w+) (-?\d+)")
_PLY_FORMAT = re.compile(rb"format (ascii|binary_little_endian|binary_big_endian) 1\.0")
_NPY_SHAPE = re.compile(rb"'shape': \((\d+),(?: (\d+))?")
_OFF_COUNTS = re.compile(rb"(\A\s*[A-Z]*OFF\s+)(\d+)")
_FIRST_INT = re.compile(rb"\d+")
_PCD_COUNT = re.compile(rb"(POINTS|WIDTH|HEIGHT) (-?\d+)")


def _pos(draw, data: bytes, *, end: bool = True) -> int:
    return draw(st.integers(0, len(data) if end else max(0, len(data) - 1)))


def _truncate(draw, name, data):
    return data[:_pos(draw, data)]


def _flip(draw, name, data):
    if not data:
        return data
    buf = bytearray(data)
    for _ in range(draw(st.integers(1, 8))):
        i = _pos(draw, data, end=False)
        buf[i] ^= draw(st.integers(1, 255))
    return bytes(buf)


def _insert_garbage(draw, name, data):
    garbage = draw(st.one_of(
        st.binary(min_size=1, max_size=48),
        st.lists(st.sampled_from(GARBAGE_TOKENS), min_size=1, max_size=6).map(lambda t: "".join(t).encode()),
    ))
    i = _pos(draw, data)
    return data[:i] + garbage + data[i:]


def _delete_run(draw, name, data):
    i = _pos(draw, data)
    return data[:i] + data[i + draw(st.integers(1, 64)):]


def _repeat_run(draw, name, data):
    i = _pos(draw, data)
    run = data[i:i + draw(st.integers(1, 80))]
    return data[:i] + run * draw(st.integers(2, 6)) + data[i:]


def _weird_number(draw, name, data):
    """Replace one number (or all numbers) of the file by NaN, inf, 1e999, huge digits ..."""
    spans = [m.span() for m in _NUMBER.finditer(data)]
    if not spans:
        return data
    value = draw(st.sampled_from(WEIRD_NUMBERS))
    if draw(st.booleans()):
        a, b = spans[draw(st.integers(0, len(spans) - 1))]
        return data[:a] + value + data[b:]
    return _NUMBER.sub(lambda m: value, data)


def _count(draw) -> int:
    return draw(st.one_of(st.sampled_from(COUNTS), st.integers(0, 2 ** 64)))


def _inflate_count(draw, name, data):
    """Make a header count claim more (or less, or a negative number of) rows than there are."""
    count = _count(draw)
    if name.startswith("ply"):
        hits = list(_PLY_ELEMENT.finditer(data))
        if hits:
            m = hits[draw(st.integers(0, len(hits) - 1))]
            return data[:m.start(2)] + str(count).encode() + data[m.end(2):]
    if name == "stl_binary" and len(data) >= 84:
        return data[:80] + struct.pack("<I", count % 2 ** 32) + data[84:]
    if name.startswith("la") and len(data) >= 111:  # LAS legacy point count, or the VLR count
        at = draw(st.sampled_from([107, 100]))
        return data[:at] + struct.pack("<I", count % 2 ** 32) + data[at + 4:]
    if name.startswith("pcd"):
        m = _PCD_COUNT.search(data)
        if m:
            return data[:m.start(2)] + str(count).encode() + data[m.end(2):]
    if name.startswith("npy"):
        m = _NPY_SHAPE.search(data)
        if m:
            group = draw(st.sampled_from([1, 2])) if m.group(2) else 1
            new = str(count).encode()
            out = data[:m.start(group)] + new + data[m.end(group):]
            # Keep the header length (the .npy length field) when the padding allows it.
            grow = len(new) - (m.end(group) - m.start(group))
            pad_end = out.find(b"\n", m.start(group))
            pad_start = len(out[:pad_end].rstrip(b" "))
            if 0 < grow <= pad_end - pad_start:
                out = out[:pad_end - grow] + out[pad_end:]
            return out
    m = _OFF_COUNTS.search(data) if name.endswith("off") else None
    if m:
        return data[:m.start(2)] + str(count).encode() + data[m.end(2):]
    m = _FIRST_INT.search(data, 0, 200)
    if m:
        return data[:m.start()] + str(count).encode() + data[m.end():]
    return data


def _swap_ply_format(draw, name, data):
    """A binary body behind an ascii header, an ascii body behind a binary one, the wrong endianness."""
    m = _PLY_FORMAT.search(data)
    if not m:
        return b"ply\nformat ascii 1.0\nelement vertex 30\nproperty float x\nproperty float y\n" \
               b"property float z\nend_header\n" + data
    new = draw(st.sampled_from([b"ascii", b"binary_little_endian", b"binary_big_endian"]))
    return data[:m.start(1)] + new + data[m.end(1):]


def _special_float(draw, name, data):
    """Write NaN, inf, 1e308, a denormal ... as a float32/float64 somewhere in the body."""
    fmt = draw(st.sampled_from(["<d", ">d", "<f", ">f"]))
    value = draw(st.sampled_from(SPECIAL_FLOATS))
    with contextlib.suppress(OverflowError):
        packed = struct.pack(fmt, value)
        i = _pos(draw, data)
        return data[:i] + packed + data[i + len(packed):]
    return data


def _splice(draw, name, data):
    """The start of this file and the end of another format's."""
    other = seeds()[draw(st.sampled_from(SEED_NAMES))][1]
    return data[:_pos(draw, data)] + other[_pos(draw, other):]


def _line_endings(draw, name, data):
    return data.replace(b"\n", draw(st.sampled_from([b"\r\n", b"\r", b"\n\n", b" \n", b"\x85"])))


def _blank(draw, name, data):
    return draw(st.sampled_from(BLANKS))


MUTATIONS = (_truncate, _flip, _insert_garbage, _delete_run, _repeat_run, _weird_number, _inflate_count,
             _swap_ply_format, _special_float, _splice, _line_endings, _blank)


@st.composite
def mutated_files(draw, min_mutations: int = 1, max_mutations: int = 3):
    """(seed name, extension, bytes): a seed file after a few mutations."""
    name = draw(st.sampled_from(SEED_NAMES))
    ext, data = seeds()[name]
    for _ in range(draw(st.integers(min_mutations, max_mutations))):
        data = draw(st.sampled_from(MUTATIONS))(draw, name, data)
    # Mostly the format's own extension; sometimes none or an unknown one (content detection).
    ext = draw(st.sampled_from([ext, ext, ext, ext, ".dat", ""]))
    return name, ext, data


# --------------------------------------------------------------------------- the property


class Hang(BaseException):
    """A reader that did not return within HANG_SECONDS (not an Exception: nothing may catch it)."""


@contextlib.contextmanager
def hang_guard(seconds: float = HANG_SECONDS):
    """Interrupt the block after ``seconds`` (SIGALRM; a no-op off the main thread or without it)."""
    if not hasattr(signal, "setitimer") or threading.current_thread() is not threading.main_thread():
        yield
        return

    def alarm(signum, frame):
        raise Hang(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


#: Inputs tried, per test and outcome ("read" or "refused"); checked at the end of the module.
COUNTER: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)


def _write_input(workdir: Path, ext: str, data: bytes) -> Path:
    path = workdir / f"input{ext}"
    path.write_bytes(data)
    return path


def check_read(path: Path, fmt: str | None = None) -> str:
    """read_points(path, fmt) returns a valid cloud or raises a one-line InputError, and warns nothing."""
    with warnings.catch_warnings(record=True) as caught, hang_guard():
        warnings.simplefilter("always")
        try:
            cloud = read_points(path, fmt)
        except InputError as exc:
            cloud, msg = None, str(exc)
    # Our own InputWarning (normals the file gives that cannot be used) is a message to the user,
    # with the file's name; anything else (numpy, plyfile) leaking out is a bug.
    ours = [w for w in caught if issubclass(w.category, InputWarning)]
    caught = [w for w in caught if not issubclass(w.category, InputWarning)]
    assert all(str(w.message).startswith(f"{path}: ") and len(str(w.message).splitlines()) == 1 for w in ours), \
        [str(w.message) for w in ours]
    if caught and os.environ.get("HOUGHCAD_FUZZ_DUMP"):
        Path(os.environ["HOUGHCAD_FUZZ_DUMP"]).write_bytes(path.read_bytes())
    assert not caught, [f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught]
    if cloud is None:
        assert msg.startswith(f"{path}: ") and len(msg) > len(f"{path}: "), msg
        assert len(msg.splitlines()) == 1, msg
        assert len(msg) - len(str(path)) <= 300, msg  # one readable line, not a dump
        return "refused"
    pts = cloud.points
    assert isinstance(pts, np.ndarray) and pts.dtype == np.float64 and pts.ndim == 2 and pts.shape[1] == 3
    n = pts.shape[0]
    assert n >= MIN_POINTS
    assert np.isfinite(pts).all()
    assert cloud.source == str(path)
    if cloud.normals is not None:
        nrm = cloud.normals
        assert nrm.dtype == np.float64 and nrm.shape == (n, 3) and np.isfinite(nrm).all()
        np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-9)
    for name, values in cloud.fields.items():
        assert np.asarray(values).shape == (n,), name
    return "read"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


# --------------------------------------------------------------------------- seeds are valid


@pytest.mark.parametrize("name", SEED_NAMES)
def test_seed_files_are_valid(workdir, name):
    ext, data = seeds()[name]
    path = _write_input(workdir, ext, data)
    cloud = read_points(path)
    assert len(cloud) >= MIN_POINTS
    check_read(path)


# --------------------------------------------------------------------------- fuzzing read_points


# Regression examples: each once made a reader fail with something other than an InputError.
@example(("ply_binary", ".ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 30\n"
          b"property float x\nproperty float y\nproperty float z\nelement junk 1000000000000\n"
          b"end_header\n" + bytes(360)))  # hang: 10^12 rows of an element without properties
@settings(_fuzz_settings("mutated", deadline_ms=3000))
@given(mutated_files())
def test_mutated_file_reads_or_fails_with_input_error(workdir, case):
    _, ext, data = case
    COUNTER["mutated"][check_read(_write_input(workdir, ext, data))] += 1


@settings(_fuzz_settings("forced_format", deadline_ms=3000))
@given(mutated_files(min_mutations=0, max_mutations=2), st.sampled_from(FORMATS))
def test_forced_format_on_any_bytes(workdir, case, fmt):
    """``read_points(path, fmt=...)`` on another format's (mutated) bytes."""
    _, ext, data = case
    COUNTER["forced_format"][check_read(_write_input(workdir, ext, data), fmt)] += 1


#: File starts that send random bytes down each reader.
MAGIC_PREFIXES = (b"", b"ply\n", b"ply\r\n", b"ply\nformat ascii 1.0\n", b"ply\nformat binary_little_endian 1.0\n",
                  b"\x93NUMPY", b"\x93NUMPY\x01\x00", b"OFF\n", b"NOFF\n", b"solid ", b"Points:=[", b"v ", b"x y z\n")


@settings(_fuzz_settings("random_bytes", deadline_ms=3000))
@given(st.sampled_from(MAGIC_PREFIXES), st.binary(max_size=400),
       st.sampled_from([".ply", ".npy", ".xyz", ".csv", ".pts", ".obj", ".off", ".stl", ".txt", ".bin", ""]))
def test_random_bytes(workdir, prefix, body, ext):
    COUNTER["random_bytes"][check_read(_write_input(workdir, ext, prefix + body))] += 1


# --------------------------------------------------------------------------- generated PLY and NPY schemas

#: PLY scalar types (numpy spelling) and property names, the odd ones included.
PLY_TYPES = ("i1", "u1", "i2", "u2", "i4", "u4", "f4", "f8")
PLY_NAMES = ("x", "y", "z", "X", "Y", "Z", "nx", "ny", "nz", "normal_x", "normal_y", "normal_z", "intensity",
             "red", "s", "vertex_indices")


def _column(rng: np.random.Generator, dtype: str, n: int, special: bool) -> np.ndarray:
    if dtype.startswith("f"):
        col = rng.uniform(-5.0, 5.0, n)
        if special and n:
            col[rng.integers(0, n, 3)] = rng.choice([np.nan, np.inf, -np.inf, 1e308, 0.0], 3)
        with np.errstate(over="ignore"):
            return col.astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(max(info.min, -100), min(info.max, 200), n, endpoint=True).astype(dtype)


@st.composite
def ply_files(draw):
    """PLY files of random schemas (types, names, list properties, several elements), valid then mutated."""
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    special = draw(st.integers(0, 3)) == 0  # a few NaN / inf / 1e308 in the float columns
    elements = []
    for _ in range(draw(st.integers(1, 2))):
        name = draw(st.sampled_from(["vertex", "vertex", "vertex", "vertex", "face", "Vertex", "points"]))
        n = draw(st.sampled_from([0, 1, 19, 20, 21, 45, 45, 60]))
        props = draw(st.lists(st.sampled_from(PLY_NAMES), min_size=0, max_size=8, unique=True))
        if draw(st.integers(0, 3)):  # mostly with x, y, z
            props = ["x", "y", "z"] + [p for p in props if p not in "xyz"]
        if not props:
            props = ["x"]
        fields, columns, len_types, val_types = [], {}, {}, {}
        for prop in props:
            dtype = draw(st.sampled_from(PLY_TYPES))
            if draw(st.integers(0, 9)) == 0:  # a list property
                lengths = rng.integers(0, 4, n)
                columns[prop] = [_column(rng, dtype, int(k), special) for k in lengths]
                fields.append((prop, object))
                len_types[prop], val_types[prop] = draw(st.sampled_from(["u1", "i4", "u4"])), dtype
            else:
                columns[prop] = _column(rng, dtype, n, special)
                fields.append((prop, dtype))
        arr = np.empty(n, dtype=fields)
        for prop, values in columns.items():
            for i in range(n):
                arr[prop][i] = values[i]
        elements.append(PlyElement.describe(arr, name, len_types=len_types, val_types=val_types))
    names = [e.name for e in elements]
    if len(set(names)) < len(names):
        elements = elements[:1]
    buf = io.BytesIO()
    PlyData(elements, text=draw(st.booleans()), byte_order=draw(st.sampled_from(["<", ">"]))).write(buf)
    data = buf.getvalue()
    if draw(st.integers(0, 2)) == 0:
        data = draw(st.sampled_from(MUTATIONS))(draw, "ply_generated", data)
    return data


#: NPY dtypes: numeric, and the ones the reader must refuse.
NPY_TYPES = ("<f8", ">f8", "<f4", "<f2", "<f16", "<i8", ">i4", "|u1", "|b1", "<c16", "<U4", "|S4", "<M8[s]",
             "<m8[s]", "|V8")
#: Mostly numeric: most generated files should get past the dtype checks.
NPY_LIKELY_TYPES = ("<f8", "<f8", "<f4", ">f8", "<i4") + NPY_TYPES
NPY_FIELDS = ("x", "y", "z", "nx", "ny", "nz", "X", "w")


@st.composite
def npy_files(draw):
    """.npy files of random dtypes (plain, structured, with sub-arrays), shapes and orders, then mutated."""
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    if draw(st.booleans()):
        names = draw(st.lists(st.sampled_from(NPY_FIELDS), min_size=1, max_size=6, unique=True))
        if draw(st.booleans()):
            names = ["x", "y", "z"] + [n for n in names if n not in "xyz"]
        dtype = np.dtype([(n, draw(st.sampled_from(NPY_LIKELY_TYPES)),
                           draw(st.sampled_from([(), (), (), (), (2,), (0,)]))) for n in names])
    else:
        dtype = np.dtype(draw(st.sampled_from(NPY_LIKELY_TYPES)))
    if draw(st.integers(0, 2)):  # mostly a table of points, (N,) for structured arrays
        rows = draw(st.sampled_from([20, 45, 60]))
        shape = (rows,) if dtype.names else (rows, draw(st.sampled_from([3, 3, 6, 4])))
    else:
        shape = tuple(draw(st.lists(st.sampled_from([0, 1, 2, 3, 6, 20, 45]), min_size=0, max_size=3)))
    raw = rng.bytes(int(np.prod(shape, dtype=np.int64)) * dtype.itemsize)
    arr = np.frombuffer(raw, dtype=dtype).reshape(shape).copy() if dtype.itemsize else np.zeros(shape, dtype)
    for field in dtype.names or [None]:  # mostly sane numbers, not just random bit patterns
        column = arr[field] if field else arr
        if column.dtype.kind in "fi" and draw(st.integers(0, 3)):
            column[...] = rng.uniform(-5.0, 5.0, column.shape) * (100 if column.dtype.kind == "i" else 1)
    if draw(st.booleans()):
        arr = np.asfortranarray(arr)
    data = _npy_bytes(arr)
    if draw(st.integers(0, 2)) == 0:
        data = draw(st.sampled_from(MUTATIONS))(draw, "npy_generated", data)
    return data


@settings(_fuzz_settings("ply_schemas", deadline_ms=3000))
@given(ply_files())
def test_generated_ply_schemas(workdir, data):
    COUNTER["ply_schemas"][check_read(_write_input(workdir, ".ply", data))] += 1


@settings(_fuzz_settings("npy_schemas", deadline_ms=3000))
@given(npy_files())
def test_generated_npy_schemas(workdir, data):
    COUNTER["npy_schemas"][check_read(_write_input(workdir, ".npy", data))] += 1


# --------------------------------------------------------------------------- the CLI on the same inputs


def _fake_result(n_points: int, source: str | None) -> Result:
    segs = [Segment(0, "plane", np.arange(0, n_points // 2, dtype=np.int64),
                    {"normal": [0.0, 0.0, 1.0], "offset": 0.0, "point": [0.0, 0.0, 0.0]}, 1e-3)]
    return Result(n_points=n_points, segments=segs, unsegmented=np.arange(n_points // 2, n_points, dtype=np.int64),
                  timing={"total": 0.1}, options={}, source=source)


@contextlib.contextmanager
def stub_pipeline():
    """``houghcad.pipeline`` without segmenting: ``segment`` answers a one-plane result at once.

    Only that one entry of ``sys.modules`` is swapped and restored (``mock.patch.dict`` would also
    drop every module first imported inside the block).
    """
    stub = types.ModuleType("houghcad.pipeline")
    stub.segment = lambda points, normals=None, **kw: _fake_result(len(points), kw.get("source"))
    name = "houghcad.pipeline"
    saved = sys.modules.get(name)
    sys.modules[name] = stub
    try:
        yield
    finally:
        if saved is None:
            del sys.modules[name]
        else:
            sys.modules[name] = saved


@contextlib.contextmanager
def captured_output():
    """Capture stdout and stderr, Python's and the file descriptors' (C libraries write there)."""
    out, err = io.StringIO(), io.StringIO()
    with tempfile.TemporaryFile() as fd_file:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = os.dup(1), os.dup(2)
        os.dup2(fd_file.fileno(), 1)
        os.dup2(fd_file.fileno(), 2)
        texts: dict[str, str] = {}
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                yield texts
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            fd_file.seek(0)
            texts.update(out=out.getvalue(), err=err.getvalue(), fd=fd_file.read().decode("utf-8", "replace"))


_CLI_RUNS = itertools.count()


@settings(_fuzz_settings("cli", deadline_ms=5000))
@given(mutated_files())
def test_cli_segment_on_mutated_files(workdir, case):
    """``houghcad segment FILE -o OUT.json``: exit 0 with the result, or exit 2 with one stderr line and
    nothing written (segmenting is stubbed: the inputs are what is fuzzed)."""
    _, ext, data = case
    folder = workdir / f"cli{next(_CLI_RUNS)}"
    folder.mkdir()
    inp = folder / f"cloud{ext}"
    inp.write_bytes(data)
    out = folder / "OUT.json"
    with stub_pipeline(), captured_output() as texts, hang_guard():
        code = main(["segment", str(inp), "-o", str(out)])
    left = sorted(p.name for p in folder.iterdir())
    assert texts["fd"] == "", texts  # nothing printed behind Python's back (LAPACK, numpy C warnings)
    COUNTER["cli"]["read" if code == 0 else "refused"] += 1
    if code == 0:
        assert left == ["OUT.json", inp.name], left
        # Nothing on stderr but our one-line warnings (normals in the file that cannot be used).
        assert out.stat().st_size > 0, texts
        assert all(line.startswith("houghcad: warning: ") for line in texts["err"].splitlines()), texts
    else:
        assert code == 2, (code, texts)
        lines = texts["err"].splitlines()
        assert len(lines) == 1 and lines[0].startswith("houghcad: error: "), texts
        assert texts["err"] == lines[0] + "\n" and texts["out"] == "", texts
        assert left == [inp.name], left  # no OUT.json, no temporary file
    shutil.rmtree(folder)


# --------------------------------------------------------------------------- inflated counts fail fast


def _peak_bytes(fn) -> int:
    """Peak memory traced (numpy's arrays included) while ``fn()`` runs."""
    tracemalloc.start()
    try:
        fn()
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peak


_PLY_XYZ = b"property double x\nproperty double y\nproperty double z\n"


@pytest.mark.parametrize("data,words", [
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n" + _PLY_XYZ + b"end_header\n"
     + bytes(24 * 30), "1000000000000 'vertex' elements"),
    (b"ply\nformat ascii 1.0\nelement vertex 1000000000\n" + _PLY_XYZ + b"end_header\n"
     + b"1 2 3\n" * 30, "1000000000 'vertex' elements"),
    # an element without properties: plyfile looped 10^12 times over nothing (a hang)
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 30\n" + _PLY_XYZ + b"element junk 1000000000000\n"
     b"end_header\n" + bytes(24 * 30), "'junk' elements"),
    (b"ply\nformat binary_big_endian 1.0\nelement vertex 30\n" + _PLY_XYZ
     + b"element face 4294967295\nproperty list uchar int vertex_indices\nend_header\n" + bytes(24 * 30), "'face'"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex -5\n" + _PLY_XYZ + b"end_header\n", "negative count"),
    (b"ply\nformat ascii 1.0\nelement vertex " + b"9" * 4000 + b"\n" + _PLY_XYZ + b"end_header\n1 2 3\n",
     "(4000 digits)"),
])
def test_inflated_ply_counts_fail_fast(workdir, data, words):
    path = _write_input(workdir, ".ply", data)
    start = time.perf_counter()
    with pytest.raises(InputError, match=re.escape(words)), hang_guard():
        read_points(path)
    assert time.perf_counter() - start < 2.0
    # nothing allocated for the claim
    assert _peak_bytes(lambda: pytest.raises(InputError, read_points, path)) < 10_000_000


@pytest.mark.parametrize("shape", ["(1000000000, 3)", "(10000000000000, 3)", "(60, 3000000000)",
                                   "(4294967296, 4294967296, 3)"])
def test_inflated_npy_shape_fails_fast(workdir, shape):
    data = seeds()["npy_f8"][1]
    header_end = data.index(b"\n", 10)
    header = data[10:header_end].replace(b"(60, 3)", shape.encode()).rstrip(b" ")
    header = header.ljust(header_end - 10, b" ")[: header_end - 10]
    assert shape.encode() in header
    path = _write_input(workdir, ".npy", data[:10] + header + data[header_end:])
    with pytest.raises(InputError, match=r"header announces shape .* more than the file's \d+ bytes"), hang_guard():
        read_points(path)
    assert _peak_bytes(lambda: pytest.raises(InputError, read_points, path)) < 10_000_000


def test_stl_triangle_count_beyond_the_file(workdir):
    data = seeds()["stl_binary"][1]
    path = _write_input(workdir, ".stl", data[:80] + struct.pack("<I", 2 ** 32 - 1) + data[84:])
    with pytest.raises(InputError, match="not a valid STL file"):
        read_points(path)


def test_off_vertex_count_beyond_the_file(workdir):
    path = _write_input(workdir, ".off", b"OFF\n" + b"9" * 400 + b" 0 0\n" + b"1 2 3\n" * 30)
    with pytest.raises(InputError, match=r"announces 9{24}\.\.\. \(400 digits\) vertices, file has 30") as exc:
        read_points(path)
    assert len(str(exc.value)) < len(str(path)) + 100


# --------------------------------------------------------------------------- regressions found by fuzzing


def test_huge_normals_stay_unit(workdir):
    """Normals near the float64 limit: their squared length overflowed and they became (0, 0, 0)."""
    pts, _ = _cloud(30, 5)
    rows = [f"{x!r} {y!r} {z!r} 1e300 -1e300 0" for x, y, z in pts.tolist()]
    check_read(_write_input(workdir, ".xyz", _text(["x y z nx ny nz"] + rows)))
    cloud = read_points(workdir / "input.xyz")
    np.testing.assert_allclose(cloud.normals[0], [2 ** -0.5, -(2 ** -0.5), 0.0])


def test_coordinates_near_the_float64_limit(workdir):
    """The degeneracy test overflowed (LAPACK complained on stderr, a line passed as a surface)."""
    pts, _ = _cloud(30, 6)
    line = np.column_stack([pts[:, 0], 0.5 * pts[:, 0], np.zeros(30)]) * 1e307 + 1e308  # up to 1.5e308
    path = _write_input(workdir, ".xyz", _text(_rows(line)))
    with pytest.raises(InputError, match="collinear"):
        read_points(path)
    check_read(_write_input(workdir, ".xyz", _text(_rows(pts * 3e307))))


def test_signalling_nan_in_a_binary_body_warns_nothing(workdir):
    """A float32 signalling NaN made numpy warn 'invalid value encountered in cast' on stderr."""
    data = bytearray(seeds()["ply_binary"][1])
    body = data.index(b"end_header\n") + len(b"end_header\n")
    data[body + 24:body + 28] = struct.pack("<I", 0x7FA00000)  # nx of the first point: a signalling NaN
    check_read(_write_input(workdir, ".ply", bytes(data)))


def test_empty_list_in_ascii_ply_warns_nothing(workdir):
    """An ascii face with an empty vertex list made plyfile's loadtxt warn 'input contained no data'."""
    pts, _ = _cloud(30, 7)
    data = _text(["ply", "format ascii 1.0", "element vertex 30", "property double x", "property double y",
                  "property double z", "element face 2", "property list uchar int vertex_indices", "end_header"]
                 + _rows(pts) + ["0", "3 0 1 2"])
    check_read(_write_input(workdir, ".ply", data))
    assert len(read_points(workdir / "input.ply")) == 30


@pytest.mark.parametrize("x_type,words", [
    (("<M8[s]",), "structured field 'x' is not numeric"),
    (("<f8", (2,)), "structured field 'x' holds 2 values per point"),
])
def test_structured_npy_with_unusable_fields(workdir, x_type, words):
    """A datetime x field raised numpy's DTypePromotionError (a TypeError), not an InputError."""
    arr = np.zeros(30, dtype=[("x", *x_type), ("y", "<f8"), ("z", "<f8")])
    with pytest.raises(InputError, match=re.escape(words)):
        read_points(_write_input(workdir, ".npy", _npy_bytes(arr)))


def test_structured_npy_with_unusable_normals_keeps_the_points(workdir):
    pts, _ = _cloud(30, 8)
    arr = np.zeros(30, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("nx", "|S4"), ("ny", "<f8"), ("nz", "<f8")])
    arr["x"], arr["y"], arr["z"] = pts.T
    cloud = read_points(_write_input(workdir, ".npy", _npy_bytes(arr)))
    assert cloud.normals is None and len(cloud) == 30


# --------------------------------------------------------------------------- the run's size


def test_at_least_2000_generated_inputs_per_run():
    """The module's fuzz tests together tried >= 2,000 inputs (when they all ran, in this order), and
    each test saw inputs read and inputs refused (mutations that always or never break a file would
    test little)."""
    if set(COUNTER) != set(EXAMPLES):
        pytest.skip(f"only {sorted(COUNTER)} of the fuzz tests ran")
    counts = {name: dict(outcomes) for name, outcomes in COUNTER.items()}
    assert sum(sum(c.values()) for c in counts.values()) >= 2000, counts
    for name, outcomes in counts.items():
        assert outcomes.get("refused", 0) > 0, (name, counts)
        # 400 random bytes never make 20 points
        assert outcomes.get("read", 0) > 0 or name == "random_bytes", (name, counts)
    print(counts)
