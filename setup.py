"""Build script. The package is declared in pyproject.toml; this file only adds ``houghcad._aot``,
the numba kernels compiled ahead of time (see ``houghcad.kernels`` for why).

The kernels are compiled with numba's ahead-of-time compiler (``numba.pycc``) for this machine's
CPU, as numba's JIT would. Any failure (no C compiler, a numba without pycc) leaves a working
install whose kernels numba compiles just in time, with a warning: the extension is optional.
"""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

SRC = Path(__file__).resolve().parent / "src"


def _compiler():
    """A numba.pycc.CC holding every kernel of houghcad.kernels.REGISTRY, each under every
    declared signature, and the numba options of each by function."""
    os.environ["HOUGHCAD_AOT_BUILD"] = "1"
    sys.path.insert(0, str(SRC))
    import importlib

    from numba.core import sigutils
    from numba.pycc import CC

    from houghcad import kernels

    for name in kernels.KERNEL_MODULES:
        importlib.import_module(name)
    cc = CC("_aot", source_module="houghcad.kernels")
    cc.target_cpu = "host"  # as numba's JIT: the extension is built where it runs
    options = {}
    for f, sigs, opts, disp in kernels.REGISTRY:
        options[f] = opts
        for i, s in enumerate(sigs):
            args, _ = sigutils.normalize_signature(f"({s},)")
            disp.compile(args)
            ret = next(o.signature.return_type for a, o in disp.overloads.items() if a == tuple(args))
            cc.export(kernels.aot_symbol(f, i), ret(*args))(f)
    digest = kernels.source_digest()
    cc.export("source_digest", "i8()")(eval(f"lambda: {digest}"))  # a constant function of the build
    return cc, options


class BuildExt(build_ext):
    """build_ext that compiles the kernels into ``houghcad._aot``, or skips it with a warning."""

    def build_extension(self, ext: Extension) -> None:
        if ext.name != "houghcad._aot":
            return super().build_extension(ext)
        try:
            import numba.pycc.compiler as pycc_compiler

            cc, options = _compiler()
            built = cc.distutils_extension()
            original = pycc_compiler.compile_extra

            def compile_extra(typingctx, targetctx, func, *args, **kwargs):
                # pycc compiles every export with default flags; give each kernel its own
                # (numpy's error model, the GIL released for the threaded kernels).
                opts = options.get(func, {})
                flags = args[2].copy()
                if "error_model" in opts:
                    flags.error_model = opts["error_model"]
                if opts.get("nogil"):
                    flags.release_gil = True
                return original(typingctx, targetctx, func, args[0], args[1], flags, *args[3:], **kwargs)

            pycc_compiler.compile_extra = compile_extra
            try:
                built._prepare_object_files(self)
            finally:
                pycc_compiler.compile_extra = original
            for attr in ("sources", "define_macros", "include_dirs", "libraries", "library_dirs",
                         "extra_compile_args", "extra_link_args", "extra_objects", "depends"):
                setattr(ext, attr, getattr(built, attr))
            super().build_extension(ext)
        except Exception as e:  # noqa: BLE001 - any failure leaves the JIT
            warnings.warn(f"houghcad: kernels not compiled ahead of time ({type(e).__name__}: {e}); "
                          "numba will compile them on first use")


setup(ext_modules=[Extension("houghcad._aot", sources=[], optional=True)], cmdclass={"build_ext": BuildExt})
