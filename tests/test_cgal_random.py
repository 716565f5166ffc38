"""The CGAL seeding workaround: it must fail loudly if the bindings' layout changes."""

from __future__ import annotations

import ctypes

import numpy as np

from houghcad import cgal_random
from houghcad.cgal_random import seed_cgal_random


def test_seed_cgal_random_writes_the_generator():
    assert seed_cgal_random(5)


def test_the_generator_symbols_are_where_the_workaround_writes():
    # The thread-local default generator and its guard must be exported by the
    # bindings' Shape_detection module under these mangled names; a CGAL with
    # another layout breaks the seeding, and this test says so.
    lib = cgal_random._cgal_shape_detection()
    ctypes.c_char.in_dll(lib, cgal_random._CGAL_RANDOM)
    ctypes.c_char.in_dll(lib, cgal_random._CGAL_RANDOM_GUARD)


def test_the_written_state_is_the_one_cgal_random_seed_would_set():
    # CGAL::Random(seed): random_value = seed % 32749 (unsigned), val 0,
    # seed, then rand48's 48-bit state (seed << 16) | 0x330E.
    assert seed_cgal_random(123456)
    lib = cgal_random._cgal_shape_detection()
    addr = ctypes.addressof(ctypes.c_char.in_dll(lib, cgal_random._CGAL_RANDOM))
    head = (ctypes.c_uint32 * 3).from_address(addr)
    assert list(head) == [123456 % 32749, 0, 123456]
    assert ctypes.c_uint64.from_address(addr + 16).value == (123456 << 16) | 0x330E
    assert np.uint32(head[2]) == 123456
