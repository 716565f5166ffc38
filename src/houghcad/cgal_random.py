"""Seeding CGAL's default random generator (a workaround, isolated here).

Efficient RANSAC draws from ``CGAL::get_default_random()``, which CGAL seeds
with ``time()``; the Python bindings expose no way to seed it. This module
writes the generator's state through ``ctypes``. ``tests/test_cgal_random.py``
fails loudly if the bindings' layout changes.
"""

from __future__ import annotations

import ctypes
import functools
import warnings


# CGAL's Random (6.x, Random_numbers/include/CGAL/Random.h): unsigned
# random_value, val, seed, then a boost::rand48 whose 48-bit state sits in a
# uint64 at offset 16; 24 bytes in all.
_CGAL_RANDOM = "_ZZN4CGAL18get_default_randomEvE14default_random"

_CGAL_RANDOM_GUARD = "_ZGVZN4CGAL18get_default_randomEvE14default_random"

_cgal_warned = False


@functools.lru_cache(maxsize=1)
def _cgal_shape_detection() -> ctypes.CDLL:
    """The bindings' Shape_detection module as a C library (loaded once)."""
    from CGAL import _CGAL_Shape_detection

    return ctypes.CDLL(_CGAL_Shape_detection.__file__)


def seed_cgal_random(seed: int) -> bool:
    """Put CGAL's default random generator, in the calling thread, in a state
    given by ``seed``, as ``CGAL::Random(seed)`` would.

    Efficient RANSAC draws from ``CGAL::get_default_random()``, which CGAL
    seeds with ``time()`` and the Python bindings expose no way to seed: two
    runs a second apart gave different pieces. The generator is a
    thread-local object of the bindings' module, found with ``dlsym``, and
    written here. Returns False (after one warning) where that fails, for
    example with a CGAL whose ``Random`` has another layout.
    """
    global _cgal_warned
    try:
        lib = _cgal_shape_detection()
        addr = ctypes.addressof(ctypes.c_char.in_dll(lib, _CGAL_RANDOM))
        guard = ctypes.c_char.in_dll(lib, _CGAL_RANDOM_GUARD)
    except (ImportError, OSError, ValueError, AttributeError):
        if not _cgal_warned:
            _cgal_warned = True
            warnings.warn("cannot seed CGAL's random generator: the RANSAC fallback of the splitting "
                          "phase may differ between runs", RuntimeWarning, stacklevel=2)
        return False
    s = int(seed) & 0xFFFFFFFF
    head = (ctypes.c_uint32 * 3).from_address(addr)
    head[0], head[1], head[2] = s % 32749, 0, s
    ctypes.c_uint64.from_address(addr + 16).value = (s << 16) | 0x330E
    # A thread-local static is constructed on first use unless its guard is
    # set; Random has a trivial destructor, so setting it is all there is.
    guard.value = b"\x01"
    return True
