"""Numba kernels: compiled ahead of time at installation, just in time otherwise (issue 20's
start-up).

A fresh process that takes numba's kernels from its cache still pays about half a second before
its first result: numba's import (0.15 s) and its compiler's first set-up (0.3 s), which loading
even one cached kernel needs. ``pip install`` therefore compiles the kernels declared here into one
extension module, ``houghcad._aot``, with numba's own ahead-of-time compiler (``numba.pycc``; see
``setup.py``), and a run with that module never imports numba.

Each kernel is declared with :func:`kernel` and the argument types it is compiled for, in numba's
notation (``"f8[:, ::1], i4[:, ::1]"``: a C-ordered float64 matrix and a C-ordered int32 matrix).
Why a dispatcher written here: pycc's exported functions take exactly their declared types and do
not check them (a float32 array where float64 is declared is read as garbage), so each call is
matched against the declared types first. A call that none takes, or a kernel without declared
types (one only other kernels call), goes to numba's JIT, imported then.

Without the extension (a source checkout that was not built, a build that failed) or with
``HOUGHCAD_JIT=1`` in the environment, every kernel is ``numba.njit(cache=True)`` as before, and
the outputs are the same: the same LLVM code, without fast-math.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import types
import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

#: Set by ``setup.py`` while it compiles the kernels: every kernel is then a numba dispatcher,
#: recorded in :data:`REGISTRY`, so that pycc compiles each with the kernels it calls.
BUILDING = os.environ.get("HOUGHCAD_AOT_BUILD") == "1"
#: The extension module's name, beside this module.
AOT_MODULE = "houghcad._aot"
#: The modules that declare kernels: ``setup.py`` imports these (they need only numpy, scipy and
#: numba, the build's requirements), and a test checks that the list is whole.
KERNEL_MODULES = ("houghcad.clusters", "houghcad.corners", "houghcad.hough", "houghcad.normals",
                  "houghcad.families._geometry", "houghcad.families._lm", "houghcad.families._noisy_profile",
                  "houghcad.families.cone", "houghcad.families.cylinder", "houghcad.families.torus")

_DTYPES = {"f8": np.dtype(np.float64), "f4": np.dtype(np.float32), "i8": np.dtype(np.int64),
           "i4": np.dtype(np.int32), "b1": np.dtype(np.bool_)}
#: Python scalar types numba types as each scalar (``typeof(1.0)`` is float64, ``typeof(1)``
#: int64): a call that numba's JIT would compile differently is not taken by the AOT code.
_SCALARS: dict[str, tuple[type, ...]] = {"f8": (float, np.float64), "i8": (int, np.int64),
                                         "b1": (bool, np.bool_)}


@dataclass(frozen=True)
class ArgType:
    """One argument's declared type: ``dtype`` code, ``ndim`` (0: a scalar) and, for arrays,
    ``layout`` ("C", "F" or "A": any strides)."""

    code: str
    ndim: int
    layout: str = "A"

    def accepts(self, a: Any) -> bool:
        if self.ndim == 0:
            return type(a) in _SCALARS[self.code]
        if type(a) is not np.ndarray or a.ndim != self.ndim or a.dtype != _DTYPES[self.code]:
            return False
        if self.layout == "C":
            return a.flags.c_contiguous
        return a.flags.f_contiguous if self.layout == "F" else True


def parse_signature(sig: str) -> tuple[ArgType, ...]:
    """The argument types of a signature string such as ``"f8[:, ::1], i8, b1"``."""
    out = []
    for part in _split_args(sig):
        code, _, dims = part.partition("[")
        code = code.strip()
        if code not in _DTYPES or (not dims and code not in _SCALARS):
            raise ValueError(f"unsupported kernel argument type {part!r} in {sig!r}")
        if not dims:
            out.append(ArgType(code, 0))
            continue
        axes = [d.strip() for d in dims.rstrip("]").split(",")]
        if not all(d in (":", "::1") for d in axes) or sum(d == "::1" for d in axes) > 1:
            raise ValueError(f"unsupported array layout {part!r} in {sig!r}")
        layout = "C" if axes[-1] == "::1" else "F" if axes[0] == "::1" and len(axes) > 1 else "A"
        out.append(ArgType(code, len(axes), layout))
    return tuple(out)


def _split_args(sig: str) -> list[str]:
    """``sig`` split at the commas outside brackets."""
    parts, depth, cur = [], 0, ""
    for ch in sig:
        depth += (ch == "[") - (ch == "]")
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    return [p for p in (*parts, cur) if p.strip()]


def aot_symbol(func: Callable, i: int) -> str:
    """The exported name of ``func``'s i-th signature in the extension module."""
    return f"{func.__module__.replace('.', '_')}__{func.__name__}__{i}"


@dataclass
class Kernel:
    """A kernel run by its ahead-of-time code where a declared signature takes the call, else by
    numba's JIT. Called like the Python function it wraps."""

    py_func: Callable
    signatures: tuple[tuple[ArgType, ...], ...]
    options: dict[str, Any]
    compiled: tuple[Callable | None, ...] = ()
    #: The signature strings as declared (numba's notation), one per entry of ``signatures``.
    declared: tuple[str, ...] = ()
    _jit: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.__name__ = self.py_func.__name__
        self.__doc__ = self.py_func.__doc__
        self.__wrapped__ = self.py_func

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if not kwargs:  # pycc's functions take their arguments by position only
            for sig, fn in zip(self.signatures, self.compiled):
                if fn is not None and len(sig) == len(args) and all(t.accepts(a) for t, a in zip(sig, args)):
                    return fn(*args)
        FALLBACKS[f"{self.py_func.__module__}.{self.__name__}"] += 1
        return self.jit()(*args, **kwargs)

    def jit(self) -> Any:
        """This kernel as a numba dispatcher, with every kernel it calls one as well."""
        if self._jit is None:
            import numba

            f = self.py_func
            g = dict(f.__globals__)
            for name in f.__code__.co_names:
                if isinstance(g.get(name), Kernel):
                    g[name] = g[name].jit()
            fn = types.FunctionType(f.__code__, g, f.__name__, f.__defaults__, f.__closure__)
            fn.__module__, fn.__qualname__ = f.__module__, f.__qualname__
            self._jit = numba.njit(cache=True, **self.options)(fn)
        return self._jit


#: Kernels declared so far, in declaration order: (Python function, signature strings, numba
#: options, the dispatcher). ``setup.py`` compiles these.
REGISTRY: list[tuple[Callable, tuple[str, ...], dict[str, Any], Any]] = []
#: Calls with types no declared signature takes, by kernel (module.name): such a call ran under
#: numba's JIT. The tests check that a run leaves this empty.
FALLBACKS: Counter[str] = Counter()


def source_digest() -> int:
    """A 62-bit digest of the kernel modules' source files. The extension holds the one it was
    built from: an editable install whose kernels changed since must not run the old code."""
    h = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for name in KERNEL_MODULES:
        h.update(here.joinpath(*name.split(".")[1:]).with_suffix(".py").read_bytes())
    return int.from_bytes(h.digest()[:8], "little") >> 2


def checked(module: Any) -> Any:
    """``module`` if it was built from the kernels' present source, else None with a warning."""
    built = getattr(module, "source_digest", None)
    if built is not None and built() == source_digest():
        return module
    warnings.warn(f"{AOT_MODULE} was built from other kernel sources than these; numba compiles the "
                  "kernels instead (reinstall houghcad to rebuild it)", RuntimeWarning, stacklevel=2)
    return None


def _load_aot() -> Any:
    if BUILDING or os.environ.get("HOUGHCAD_JIT") == "1":
        return None
    try:
        return checked(importlib.import_module(AOT_MODULE))
    except ImportError:
        return None


_AOT = _load_aot()


def aot_loaded() -> bool:
    """Whether the kernels run from the ahead-of-time extension module."""
    return _AOT is not None


def kernel(*signatures: str, **options: Any) -> Callable[[Callable], Any]:
    """Declare a numba kernel and the argument types it is compiled for ahead of time.

    ``signatures`` are numba argument-type strings (no return type: numba infers it); a kernel
    only other kernels call declares none. ``options`` go to ``numba.njit`` (``nogil``,
    ``inline``, ``error_model``); ``cache=True`` always.
    """
    sigs = tuple(parse_signature(s) for s in signatures)

    def wrap(f: Callable) -> Any:
        if _AOT is None:
            import numba

            disp = numba.njit(cache=True, **options)(f)
            if BUILDING:
                REGISTRY.append((f, signatures, dict(options), disp))
            return disp
        compiled = tuple(getattr(_AOT, aot_symbol(f, i), None) for i in range(len(sigs)))
        return Kernel(f, sigs, dict(options), compiled, signatures)

    return wrap
