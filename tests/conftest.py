"""Test-wide settings: the state's invariants are checked after every pass."""

from __future__ import annotations

import os

os.environ.setdefault("HOUGHCAD_CHECK", "1")
