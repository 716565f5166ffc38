"""The numba kernels: compiled ahead of time when the extension is built, the same answers as
numba's JIT, and a process that never imports numba."""

from __future__ import annotations

import importlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from houghcad import kernels
from houghcad.kernels import ArgType, Kernel, aot_loaded, parse_signature

SRC = Path(kernels.__file__).resolve().parent
needs_aot = pytest.mark.skipif(not aot_loaded(), reason="houghcad._aot not built (a JIT-only install)")


def test_parse_signature_reads_layouts_and_scalars() -> None:
    sig = parse_signature("f8[:, ::1], i4[::1, :], b1[:], i8, f8")
    assert sig == (ArgType("f8", 2, "C"), ArgType("i4", 2, "F"), ArgType("b1", 1, "A"), ArgType("i8", 0),
                   ArgType("f8", 0))
    for bad in ("f2[::1]", "f4", "f8[::2]", "f8[::1, ::1]"):
        with pytest.raises(ValueError):
            parse_signature(bad)


def test_arg_types_accept_what_numba_types_alike() -> None:
    c = ArgType("f8", 2, "C")
    a = np.zeros((4, 3))
    assert c.accepts(a)
    assert not c.accepts(a.astype(np.float32))  # pycc would read float32 bytes as float64
    assert not c.accepts(a[:, :2])  # not contiguous
    assert not c.accepts(np.zeros(12))
    assert ArgType("f8", 2, "F").accepts(np.asfortranarray(a))
    assert ArgType("f8", 2, "A").accepts(a[:, :2])
    f, i, b = ArgType("f8", 0), ArgType("i8", 0), ArgType("b1", 0)
    assert f.accepts(1.5) and f.accepts(np.float64(1.5)) and not f.accepts(1) and not f.accepts(np.float32(1))
    assert i.accepts(3) and i.accepts(np.int64(3)) and not i.accepts(True) and not i.accepts(np.int32(3))
    assert b.accepts(True) and b.accepts(np.bool_(False)) and not b.accepts(1)


def test_kernel_modules_list_every_module_that_declares_kernels() -> None:
    declaring = set()
    for path in SRC.rglob("*.py"):
        if path.name != "kernels.py" and re.search(r"^@kernel\(", path.read_text(), re.M):
            declaring.add(".".join(("houghcad", *path.relative_to(SRC).with_suffix("").parts)))
    assert declaring == set(kernels.KERNEL_MODULES)


def _kernels() -> list[Kernel]:
    out = []
    for name in kernels.KERNEL_MODULES:
        out += [v for v in vars(importlib.import_module(name)).values() if isinstance(v, Kernel)]
    return out


@needs_aot
def test_every_declared_signature_is_in_the_extension() -> None:
    ks = _kernels()
    assert len(ks) >= 20
    for k in ks:
        assert len(k.compiled) == len(k.signatures)
        assert all(fn is not None for fn in k.compiled), f"{k.__name__}: the extension is older than its code"


@needs_aot
def test_a_call_no_signature_takes_runs_under_the_jit_with_the_same_answer() -> None:
    from houghcad.families import _lm

    v = np.arange(10.0)
    before = kernels.FALLBACKS.copy()
    assert _lm._norm(v) == pytest.approx(np.linalg.norm(v))
    assert kernels.FALLBACKS == before
    assert _lm._norm(v[::2]) == pytest.approx(np.linalg.norm(v[::2]))  # strided: not f8[::1]
    assert kernels.FALLBACKS - before == {"houghcad.families._lm._norm": 1}
    assert _lm._norm(v=v) == pytest.approx(np.linalg.norm(v))  # by keyword: the JIT's too
    assert kernels.FALLBACKS - before == {"houghcad.families._lm._norm": 2}


@needs_aot
def test_every_kernel_has_a_jit_fallback_for_its_signatures() -> None:
    from numba.core import sigutils

    for k in _kernels():
        disp = k.jit()
        assert len(k.declared) == len(k.signatures)
        for sig in k.declared:
            args, _ = sigutils.normalize_signature(f"({sig},)")
            disp.compile(args)  # the kernels it calls resolve to numba dispatchers too
        assert len(disp.overloads) >= len(k.signatures)


_RUN = """
import json, sys
import houghcad
from houghcad import kernels, synth
res = []
for name, fams, noise in (("gear_like", "simple", 0.0), ("shaft_with_groove", "simple", 0.005),
                          ("screw_part", "all", 0.005)):
    pts = synth.PARTS[name](seed=0, n_points=4000, noise=noise).points
    r = houghcad.segment(pts, families=fams, seed=0, n_jobs=1)
    res.append([[s.type, s.indices.tolist(), repr(sorted(s.params.items()))] for s in r.segments])
print(json.dumps(dict(aot=kernels.aot_loaded(), numba="numba" in sys.modules,
                      fallbacks=dict(kernels.FALLBACKS), segments=res)))
"""


def _run(jit: bool) -> dict:
    env = {**os.environ, "HOUGHCAD_JIT": "1" if jit else "0"}
    out = subprocess.run([sys.executable, "-c", _RUN], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@needs_aot
def test_ahead_of_time_run_matches_the_jit_and_never_imports_numba() -> None:
    aot, jit = _run(jit=False), _run(jit=True)
    assert aot["aot"] and not jit["aot"]
    assert not aot["numba"] and jit["numba"]
    assert aot["fallbacks"] == {}  # every call the pipeline makes has its compiled signature
    assert aot["segments"] == jit["segments"]
    assert all(len(s) >= 3 for s in aot["segments"])


def test_an_extension_built_from_other_sources_is_refused() -> None:
    class Stale:
        @staticmethod
        def source_digest() -> int:
            return kernels.source_digest() ^ 1

    with pytest.warns(RuntimeWarning, match="other kernel sources"):
        assert kernels.checked(Stale()) is None
    with pytest.warns(RuntimeWarning):
        assert kernels.checked(object()) is None  # built before it held a digest

    class Fresh:
        @staticmethod
        def source_digest() -> int:
            return kernels.source_digest()

    fresh = Fresh()
    assert kernels.checked(fresh) is fresh
