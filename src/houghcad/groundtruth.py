"""Fit4CAD ground-truth readers (segments, types, parameters), used by :mod:`houghcad.evaluate`.

Fit4CAD files (see ``shared/fit4cad/README.md``):

- ``PCn_primitives.txt``: blocks ``PrimitiveK:=[i j k ...];`` of 1-based point indices.
- ``PCn_implicit.txt`` / ``PCn_parametric.txt``: blocks ``PrimitiveK:=[Type, [numbers]];``.

Block correspondence: the k-th block of ``_primitives.txt`` describes the same surface as the k-th
block of ``_parametric.txt`` (by position, not by the number K). Checked on all 188 training
clouds: in one of them the primitives blocks are numbered 1-4, 7-23 while the parametric ones are
1-21, and only the positional pairing puts the points on the decoded surfaces. ``_implicit.txt``
omits the blocks of B-spline surfaces (two clouds have some), so it is *not* aligned there;
use ``_parametric.txt`` for types.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError

__all__ = ["read_fit4cad_segments", "read_fit4cad_types", "read_fit4cad_parameters"]

# ``PrimitiveK:=[ ... ]`` (also ``PrimitiveK :=[``); index lists contain no nested brackets.
_INDEX_BLOCK = re.compile(r"Primitive\s*(\d+)\s*:=\s*\[([^\[\]]*)\]")
# ``PrimitiveK:=[Type, ...];`` -- body runs to the first ``;`` (bodies hold no ``;``).
_TYPED_BLOCK = re.compile(r"Primitive\s*(\d+)\s*:=\s*\[\s*([A-Za-z][A-Za-z_]*)\s*,([^;]*);?")
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_INDEX_BODY = re.compile(r"[\d\s,]*")
_TYPE_NAMES = {
    "plane": "plane",
    "cylinder": "cylinder",
    "cone": "cone",
    "sphere": "sphere",
    "torus": "torus",
    "bspline": "bspline",
}


def read_text(path: str | Path) -> str:
    """A UTF-8 text file's content; OS and decoding errors become one-line InputErrors."""
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError:
        raise InputError(f"{p}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{p}: is a directory, expected a file") from None
    except UnicodeDecodeError:
        raise InputError(f"{p}: not a UTF-8 text file") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror})") from None


def read_fit4cad_segments(path: str | Path) -> list[np.ndarray]:
    """Read a Fit4CAD ``_primitives.txt`` ground-truth segmentation.

    Parameters
    ----------
    path : str or Path
        File with blocks ``PrimitiveK:=[i j k ...];`` (1-based point indices; ``PrimitiveK :=[``
        is accepted too).

    Returns
    -------
    list of ndarray of int64, each shape (M_k,)
        0-based point indices of each block, blocks sorted by K (which is file order in every
        training file), indices in file order (not necessarily sorted; not deduplicated).

    Raises
    ------
    InputError
        Missing/unreadable file, no blocks, a repeated K, a non-integer entry, or index 0.
    """
    text = read_text(path)
    blocks: dict[int, np.ndarray] = {}
    for m in _INDEX_BLOCK.finditer(text):
        k = int(m.group(1))
        body = m.group(2)
        if not _INDEX_BODY.fullmatch(body):
            bad = re.search(r"[^\d\s,]+", body)
            raise InputError(
                f"{path}: Primitive{k} holds a non-integer entry {bad.group(0)[:20]!r}"
                if bad
                else f"{path}: Primitive{k} is malformed"
            )
        if k in blocks:
            raise InputError(f"{path}: Primitive{k} appears twice")
        # str.split + one numpy conversion: no per-point Python work.
        try:
            idx = np.array(body.replace(",", " ").split(), dtype=np.int64)
        except OverflowError:
            raise InputError(f"{path}: Primitive{k} holds an index beyond any cloud's size") from None
        if idx.size and idx.min() < 1:
            raise InputError(f"{path}: Primitive{k} has index {int(idx.min())}; indices are 1-based")
        blocks[k] = idx - 1
    if not blocks:
        raise InputError(f"{path}: no 'PrimitiveK:=[...]' blocks found")
    return [blocks[k] for k in sorted(blocks)]


def _typed_blocks(path: str | Path) -> list[tuple[int, str, str]]:
    """(K, lowercase type, raw body) of each ``PrimitiveK:=[Type, ...]`` block, sorted by K."""
    text = read_text(path)
    out: dict[int, tuple[int, str, str]] = {}
    for m in _TYPED_BLOCK.finditer(text):
        k = int(m.group(1))
        if k in out:
            raise InputError(f"{path}: Primitive{k} appears twice")
        name = m.group(2).lower()
        out[k] = (k, _TYPE_NAMES.get(name, name), m.group(3))
    if not out:
        raise InputError(f"{path}: no 'PrimitiveK:=[Type, ...]' blocks found")
    return [out[k] for k in sorted(out)]


def read_fit4cad_types(path: str | Path) -> list[str]:
    """Lowercase type of each block of a ``_implicit.txt`` or ``_parametric.txt`` file.

    Returns
    -------
    list of str
        ``"plane"``, ``"cylinder"``, ``"cone"``, ``"sphere"``, ``"torus"`` (and ``"bspline"``,
        which two parametric files of the training set contain), blocks sorted by K. Read the
        ``_parametric.txt`` file to get one entry per ground-truth segment: implicit files omit
        B-spline blocks.
    """
    return [t for _, t, _ in _typed_blocks(path)]


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` scaled to length 1 (a zero vector is returned as it is)."""
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


def _decode(kind: str, values: np.ndarray) -> dict[str, Any]:
    """Named parameters (result.py names) from a parametric block's numbers; {} if unknown."""
    # Every layout below is a 3 x m matrix stored column by column; see read_fit4cad_parameters.
    sizes = {"plane": 9, "cylinder": 12, "cone": 18, "sphere": 12, "torus": 18}
    if sizes.get(kind) != values.size:
        return {}
    cols = values.reshape(-1, 3)  # row j = column j of the matrix
    if kind == "plane":
        u, v, p = cols
        n = unit(np.cross(u, v))
        return {"normal": n, "offset": float(n @ p), "point": p}
    if kind == "cylinder":
        ru, _rv, a, p = cols
        return {"axis_point": p, "axis": unit(a), "radius": float(np.linalg.norm(ru))}
    if kind == "sphere":
        ru, _rv, _rw, c = cols
        return {"center": c, "radius": float(np.linalg.norm(ru))}
    if kind == "cone":
        big_r_u, _big_r_v, s_u, _s_v, c_a, p = cols
        big_r, s, c = (float(np.linalg.norm(x)) for x in (big_r_u, s_u, c_a))
        if s <= 0 or c <= 0:
            return {}
        a = c_a / c
        # Radius R + t*s vanishes at t = -R/s: that is the apex.
        return {"apex": p - (big_r / s) * c * a, "axis": a, "half_angle": math.atan2(s, c)}
    if kind == "torus":
        big_r_u, _big_r_v, r_u, _r_v, r_a, c = cols
        return {
            "center": c,
            "axis": unit(r_a),
            "major_radius": float(np.linalg.norm(big_r_u)),
            "minor_radius": float(np.linalg.norm(r_u)),
        }
    return {}


def read_fit4cad_parameters(path_parametric: str | Path) -> list[dict[str, Any]]:
    """Best-effort decoding of a Fit4CAD ``_parametric.txt`` file.

    Each block ``PrimitiveK:=[Type, [v1 v2 ...]]`` is a 3 x m matrix ``M`` stored column by
    column (``M[:, j] = v[3j:3j+3]``) such that a surface point is ``M @ b`` for the basis ``b``
    below (u, v, w unit and mutually orthogonal, a = unit axis, p a point; angles theta, phi):

    - plane (9 numbers): columns ``u, v, p``; ``x = s u + t v + p``; normal = u x v.
    - cylinder (12): columns ``r u, r v, a, p``; ``b = (cos th, sin th, t, 1)``.
    - sphere (12): columns ``r u, r v, r w, c``; ``b = (cos ph cos th, cos ph sin th, sin ph, 1)``.
    - cone (18): columns ``R u, R v, s u, s v, c a, p`` with ``s = sin(alpha), c = cos(alpha)``
      (alpha = half angle) and ``R`` the radius at ``p``;
      ``b = (cos th, sin th, t cos th, t sin th, t, 1)``, i.e. radius ``R + t s`` at height
      ``t c``. Apex = ``p - (R/s) c a``; ``a`` points from the apex into the opening.
    - torus (18): columns ``R u, R v, r u, r v, r a, c`` (R major, r minor radius);
      ``b = (cos th, sin th, cos ph cos th, cos ph sin th, sin ph, 1)``.

    Confirmed on all 188 training clouds (2669 analytic blocks) by measuring the distance of each
    ground-truth segment's points to the decoded surface: the 95th percentile is below 1e-3 of
    the cloud's bounding-box diagonal for every block except two cylinders whose axis point
    lies 5e5 units away (the file's 6 significant digits tilt the axis). Also confirmed: column
    norms as stated (``|r u| = |r v|``, ``|a| = 1``, ``s^2 + c^2 = 1``), and every cone's ground-truth
    points lie on the ``+a`` side of the decoded apex. A torus block may be written
    ``[Torus, [Torus, [...]]``; the repeated type word is ignored.

    Returns
    -------
    list of dict, one per block sorted by K
        ``"type"`` (lowercase), ``"values"`` (list of float, the raw numbers) and, when the
        layout is the one above, the decoded parameters under the names of ``houghcad.result``
        (lengths in the cloud's units, angles in radians, vectors as float64 arrays of shape (3,)):
        plane ``normal, offset, point``; cylinder ``axis_point, axis, radius``; cone ``apex, axis,
        half_angle``; sphere ``center, radius``; torus ``center, axis, major_radius,
        minor_radius``. B-spline blocks (empty lists) carry no decoded fields.
    """
    out: list[dict[str, Any]] = []
    for _, kind, body in _typed_blocks(path_parametric):
        values = np.array([float(x) for x in _NUMBER.findall(body)], dtype=np.float64)
        entry: dict[str, Any] = {"type": kind, "values": values.tolist()}
        entry.update(_decode(kind, values))
        out.append(entry)
    return out
