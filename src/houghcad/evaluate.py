"""Evaluation against Fit4CAD ground truth: file readers and classification measures.

Fit4CAD files (see ``shared/fit4cad/README.md``):

- ``PCn_primitives.txt``: blocks ``PrimitiveK:=[i j k ...];`` of 1-based point indices.
- ``PCn_implicit.txt`` / ``PCn_parametric.txt``: blocks ``PrimitiveK:=[Type, [numbers]];``.

Block correspondence: the k-th block of ``_primitives.txt`` describes the same surface as the k-th
block of ``_parametric.txt`` (by position, not by the number K). Checked on all 188 training
clouds: in PC83 the primitives blocks are numbered 1-4, 7-23 while the parametric ones are 1-21,
and only the positional pairing puts the points on the decoded surfaces. ``_implicit.txt`` omits
the blocks of B-spline surfaces (PC117, PC144), so it is *not* aligned with the other two there;
use ``_parametric.txt`` for types.

The classification measures follow the README's definitions; see :func:`classification_measures`.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from .errors import InputError
from .result import Result

__all__ = [
    "read_fit4cad_segments",
    "read_fit4cad_types",
    "read_fit4cad_parameters",
    "classification_measures",
    "mfe_stats",
    "parameter_errors",
    "PARAMETER_TOLERANCES",
    "ground_truth_for",
    "evaluate_files",
    "MEASURES",
]

#: Names of the averaged measures, in the order the benchmark reports them.
MEASURES: tuple[str, ...] = ("DSC", "PPV", "TPR", "TNR", "NPV", "ACC")

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


def _read_text(path: str | Path) -> str:
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


# --------------------------------------------------------------------------- readers


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
    text = _read_text(path)
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
        idx = np.array(body.replace(",", " ").split(), dtype=np.int64)
        if idx.size and idx.min() < 1:
            raise InputError(f"{path}: Primitive{k} has index {int(idx.min())}; indices are 1-based")
        blocks[k] = idx - 1
    if not blocks:
        raise InputError(f"{path}: no 'PrimitiveK:=[...]' blocks found")
    return [blocks[k] for k in sorted(blocks)]


def _typed_blocks(path: str | Path) -> list[tuple[int, str, str]]:
    """(K, lowercase type, raw body) of each ``PrimitiveK:=[Type, ...]`` block, sorted by K."""
    text = _read_text(path)
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
        which the parametric files of PC117 and PC144 contain), blocks sorted by K. Read the
        ``_parametric.txt`` file to get one entry per ground-truth segment: implicit files omit
        B-spline blocks.
    """
    return [t for _, t, _ in _typed_blocks(path)]


def _unit(v: np.ndarray) -> np.ndarray:
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
        n = _unit(np.cross(u, v))
        return {"normal": n, "offset": float(n @ p), "point": p}
    if kind == "cylinder":
        ru, _rv, a, p = cols
        return {"axis_point": p, "axis": _unit(a), "radius": float(np.linalg.norm(ru))}
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
            "axis": _unit(r_a),
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
    the cloud's bounding-box diagonal for every block except two PC66 cylinders whose axis point
    lies 5e5 units away (the file's 6 significant digits tilt the axis). Also confirmed: column
    norms as stated (``|r u| = |r v|``, ``|a| = 1``, ``s^2 + c^2 = 1``), and every cone's ground-truth
    points lie on the ``+a`` side of the decoded apex. PC1's torus block is written
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


# --------------------------------------------------------------------------- measures


def _membership(segments: list[np.ndarray], n_points: int, what: str) -> sp.csr_matrix:
    """Boolean (n_segments, n_points) CSR membership matrix; duplicates within a segment count once."""
    lengths = np.fromiter((len(s) for s in segments), dtype=np.int64, count=len(segments))
    cols = (
        np.concatenate([np.asarray(s, dtype=np.int64).ravel() for s in segments])
        if segments
        else np.zeros(0, dtype=np.int64)
    )
    if cols.size and (cols.min() < 0 or cols.max() >= n_points):
        bad = int(cols[(cols < 0) | (cols >= n_points)][0])
        seg = int(np.searchsorted(np.cumsum(lengths), np.flatnonzero(cols == bad)[0], side="right"))
        raise InputError(f"{what} segment {seg}: index {bad} out of range [0, {n_points})")
    rows = np.repeat(np.arange(len(segments), dtype=np.int64), lengths)
    m = sp.csr_matrix(
        (np.ones(cols.size, dtype=np.int64), (rows, cols)), shape=(len(segments), n_points)
    )
    m.sum_duplicates()
    m.data[:] = 1  # a point listed twice in one segment is still one point
    return m


def _ratio(num: np.ndarray, den: np.ndarray, if_zero: float) -> np.ndarray:
    out = np.full(num.shape, if_zero, dtype=np.float64)
    ok = den > 0
    out[ok] = num[ok] / den[ok]
    return out


def classification_measures(
    pred_segments: list[np.ndarray],
    gt_segments: list[np.ndarray],
    n_points: int,
    *,
    per_segment: bool = False,
) -> dict[str, Any]:
    """Fit4CAD classification measures of one cloud, averaged over ground-truth segments.

    Parameters
    ----------
    pred_segments : list of int arrays, each shape (M_j,)
        Predicted segments, 0-based point indices. Segments may overlap.
    gt_segments : list of int arrays, each shape (G_i,)
        Ground-truth segments, 0-based. Points may be in two segments or in none.
    n_points : int
        Number of points in the cloud; every index must be in ``[0, n_points)``.
    per_segment : bool
        Also return per-GT-segment arrays under ``"per_segment"``.

    Returns
    -------
    dict
        ``"DSC", "PPV", "TPR", "TNR", "NPV", "ACC"``: floats, means over the GT segments (NaN when
        there is no GT segment). With ``per_segment``: ``"per_segment"`` maps those names and
        ``"TP", "FP", "FN", "TN"`` to arrays of shape (n_gt,), plus ``"match"`` (index of the
        matched predicted segment, -1 if none).

    Notes
    -----
    Reading of the README: U = union of all GT segments. Each GT segment G is matched with the
    predicted segment P sharing the most points with it (ties: the lowest prediction index, as
    MATLAB's ``max`` does); if none shares a point, P = {} (unmatched). Then TP = |G n P|,
    FP = |P n U| - TP, FN = |G| - TP, TN = |U| - TP - FP - FN, and
    DSC = 2 TP / (|G| + |P|) with |P| the *full* size of the predicted segment, points outside U
    included (the README writes |P|, not |P n U|), so predicting points that no GT segment
    contains lowers DSC but not PPV. PPV = TP/(TP+FP), TPR = TP/(TP+FN), TNR = TN/(TN+FP),
    NPV = TN/(TN+FN), ACC = (TP+TN)/|U|.

    Zero denominators: an unmatched G scores DSC = PPV = TPR = 0 (a missed segment must not earn
    perfect precision); TNR = 1 when TN+FP = 0 (G covers U: no negatives to get wrong) and NPV = 1
    when TN+FN = 0 (nothing predicted negative, so no wrong negative prediction). Duplicate
    indices within one segment count once.
    """
    n_points = int(n_points)
    if n_points < 0:
        raise InputError(f"n_points must be >= 0, got {n_points}")
    G = _membership(list(gt_segments), n_points, "ground-truth")
    P = _membership(list(pred_segments), n_points, "predicted")
    n_gt, n_pred = G.shape[0], P.shape[0]

    in_u = np.asarray(G.sum(axis=0)).ravel() > 0  # (n_points,) point belongs to some GT segment
    size_u = int(in_u.sum())
    size_g = np.asarray(G.sum(axis=1)).ravel()  # (n_gt,)
    size_p = np.asarray(P.sum(axis=1)).ravel()  # (n_pred,)
    size_p_in_u = P @ in_u.astype(np.int64)  # (n_pred,) |P n U|

    tp = np.zeros(n_gt, dtype=np.int64)
    match = np.full(n_gt, -1, dtype=np.int64)
    if n_pred and n_gt:
        overlap = (G @ P.T).toarray()  # (n_gt, n_pred) |G_i n P_j|, one sparse product
        best = overlap.argmax(axis=1)  # first maximum: MATLAB's tie rule
        tp = overlap[np.arange(n_gt), best].astype(np.int64)
        match = np.where(tp > 0, best, -1)  # sharing no point = unmatched, P = {}
    matched = match >= 0
    safe = np.maximum(match, 0)  # valid gather index; masked out below when unmatched
    p_size = np.where(matched, size_p[safe] if n_pred else 0, 0)
    p_in_u = np.where(matched, size_p_in_u[safe] if n_pred else 0, 0)

    fp = p_in_u - tp
    fn = size_g - tp
    tn = size_u - tp - fp - fn
    per = {
        "DSC": _ratio(2.0 * tp, (size_g + p_size).astype(np.float64), 0.0),
        "PPV": _ratio(tp.astype(np.float64), (tp + fp).astype(np.float64), 0.0),
        "TPR": _ratio(tp.astype(np.float64), (tp + fn).astype(np.float64), 0.0),
        "TNR": _ratio(tn.astype(np.float64), (tn + fp).astype(np.float64), 1.0),
        "NPV": _ratio(tn.astype(np.float64), (tn + fn).astype(np.float64), 1.0),
        "ACC": _ratio((tp + tn).astype(np.float64), np.full(n_gt, float(size_u)), 0.0),
    }
    out: dict[str, Any] = {k: (float(v.mean()) if n_gt else float("nan")) for k, v in per.items()}
    if per_segment:
        out["per_segment"] = {
            **per,
            "TP": tp.astype(np.int64),
            "FP": fp.astype(np.int64),
            "FN": fn.astype(np.int64),
            "TN": tn.astype(np.int64),
            "match": match.astype(np.int64),
        }
    return out


def mfe_stats(result: Result) -> dict[str, float]:
    """Min, mean and max of the segments' mean fitting errors (MFE, dimensionless).

    Non-finite MFEs (segments without a fit) are ignored; all three are NaN when no segment has a
    finite MFE.
    """
    mfe = np.array([s.mfe for s in result.segments], dtype=np.float64)
    mfe = mfe[np.isfinite(mfe)]
    if mfe.size == 0:
        return {"min": float("nan"), "mean": float("nan"), "max": float("nan")}
    return {"min": float(mfe.min()), "mean": float(mfe.mean()), "max": float(mfe.max())}


# --------------------------------------------------------------------------- parameters

#: Issue 2's acceptance figures for simple primitives: degrees for ``*_deg``, fractions of the
#: cloud's diagonal otherwise.
PARAMETER_TOLERANCES: dict[str, float] = {
    "normal_deg": 1.0, "axis_deg": 1.0, "half_angle_deg": 1.0, "offset": 0.01, "radius": 0.01,
    "axis_line": 0.01, "apex": 0.01, "center": 0.01, "major": 0.01, "minor": 0.01}


def _angle_deg(a, b, oriented: bool = False) -> float:
    c = float(_unit(np.asarray(a, float)) @ _unit(np.asarray(b, float)))
    return float(np.degrees(np.arccos(np.clip(c if oriented else abs(c), -1.0, 1.0))))


def _axis_line_distance(truth: dict, found: dict, points: np.ndarray) -> float:
    """Largest distance from the true axis line to the found one over the object's extent (the
    true axis points at both ends of the points' projection onto it)."""
    a, p = _unit(np.asarray(truth["axis"], float)), np.asarray(truth["axis_point"], float)
    d, q = _unit(np.asarray(found["axis"], float)), np.asarray(found["axis_point"], float)
    h = (points - p) @ a
    out = 0.0
    for t in (h.min(), h.max()):
        w = p + t * a - q
        out = max(out, float(np.linalg.norm(w - (w @ d) * d)))
    return out


def parameter_errors(family: str, truth: dict, found: dict, diagonal: float,
                     points: np.ndarray) -> dict[str, float]:
    """Errors of a simple primitive's world parameters ``found`` against ``truth``.

    Parameters
    ----------
    family : {"plane", "cylinder", "cone", "sphere", "torus"}
    truth, found : dict
        Named parameters as in the JSON output (a plane's truth needs a ``point``).
    diagonal : float
        The cloud's bounding-box diagonal (world units).
    points : ndarray, shape (n, 3)
        The object's points: the axis-line error is measured over their extent.

    Returns
    -------
    dict
        Angles in degrees (keys ``*_deg``), lengths and positions as fractions of ``diagonal``;
        compare with :data:`PARAMETER_TOLERANCES`. A plane's offset error is the distance of the
        true patch's point to the found plane, so a small normal error is not multiplied by the
        distance of the pose from the origin.
    """
    v = lambda x: np.asarray(x, float)  # noqa: E731
    if family == "plane":
        return {"normal_deg": _angle_deg(truth["normal"], found["normal"]),
                "offset": abs(float(_unit(v(found["normal"])) @ v(truth["point"])) - float(found["offset"]))
                / diagonal}
    if family == "cylinder":
        return {"axis_deg": _angle_deg(truth["axis"], found["axis"]),
                "radius": abs(found["radius"] - truth["radius"]) / diagonal,
                "axis_line": _axis_line_distance(truth, found, points) / diagonal}
    if family == "cone":
        return {"axis_deg": _angle_deg(truth["axis"], found["axis"], oriented=True),
                "half_angle_deg": abs(float(np.degrees(found["half_angle"] - truth["half_angle"]))),
                "apex": float(np.linalg.norm(v(found["apex"]) - v(truth["apex"]))) / diagonal}
    if family == "sphere":
        return {"center": float(np.linalg.norm(v(found["center"]) - v(truth["center"]))) / diagonal,
                "radius": abs(found["radius"] - truth["radius"]) / diagonal}
    if family == "torus":
        return {"axis_deg": _angle_deg(truth["axis"], found["axis"]),
                "center": float(np.linalg.norm(v(found["center"]) - v(truth["center"]))) / diagonal,
                "major": abs(found["major_radius"] - truth["major_radius"]) / diagonal,
                "minor": abs(found["minor_radius"] - truth["minor_radius"]) / diagonal}
    raise ValueError(f"parameter_errors: unknown family {family!r}")


# --------------------------------------------------------------------------- files


#: Point-cloud file extensions :func:`ground_truth_for` strips (those of ``houghcad.io.readers``).
_CLOUD_EXTENSIONS = (".ply", ".xyz", ".txt", ".csv", ".pts", ".asc", ".npy", ".obj", ".off", ".stl")


def ground_truth_for(path: str | Path) -> Path:
    """Locate the ``_primitives.txt`` ground truth for a point cloud.

    Accepts ``NAME_primitives.txt`` itself, the cloud ``NAME.<ext>`` for any point-cloud
    extension houghcad reads (``.ply .xyz .txt .csv .pts .asc .npy .obj .off .stl``, any case),
    a sibling ``NAME_implicit.txt`` / ``NAME_parametric.txt``, or the prefix ``.../NAME``; the
    ground truth is ``NAME_primitives.txt`` in the same folder.
    """
    p = Path(path)
    name = p.name
    if name.endswith("_primitives.txt"):
        cand = p
    else:
        stem = name
        for ext in _CLOUD_EXTENSIONS:
            if stem.lower().endswith(ext) and len(stem) > len(ext):
                stem = stem[: -len(ext)]
                break
        for suffix in ("_implicit", "_parametric"):
            stem = stem.removesuffix(suffix)
        cand = p.with_name(stem + "_primitives.txt")
    if not cand.is_file():
        raise InputError(f"{path}: ground truth {cand.name} not found")
    return cand


def evaluate_files(result_json_path: str | Path, ground_truth_path: str | Path) -> dict[str, Any]:
    """Evaluate a saved :class:`Result` (JSON of ``Result.to_dict()``) against Fit4CAD ground truth.

    Parameters
    ----------
    result_json_path : str or Path
        JSON file written from ``Result.to_dict()``.
    ground_truth_path : str or Path
        Anything :func:`ground_truth_for` accepts.

    Returns
    -------
    dict
        ``{"measures": {"DSC", "PPV", "TPR", "TNR", "NPV", "ACC"}, "mfe": {"min", "mean", "max"},
        "n_gt": int, "n_pred": int}``.
    """
    rpath = Path(result_json_path)
    text = _read_text(rpath)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{rpath}: malformed JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(data, dict):
        raise InputError(f"{rpath}: expected a JSON object, got {type(data).__name__}")
    for key in ("n_points", "segments"):
        if key not in data:
            raise InputError(f"{rpath}: missing key {key!r}")
    try:
        result = Result.from_dict(data)
    except KeyError as exc:
        raise InputError(f"{rpath}: a segment lacks key {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{rpath}: invalid result ({exc})") from None

    if result.n_points < 0:
        raise InputError(f"{rpath}: n_points is negative ({result.n_points})")
    gt_file = ground_truth_for(ground_truth_path)
    gt = read_fit4cad_segments(gt_file)
    n = result.n_points
    gt_max = max((int(g.max()) for g in gt if g.size), default=-1)
    if gt_max >= n:
        raise InputError(
            f"{gt_file}: index {gt_max + 1} (1-based) exceeds the result's n_points {n}"
        )
    for s in result.segments:
        idx = s.indices
        if idx.ndim != 1:
            raise InputError(f"{rpath}: segment {s.id} indices are not a flat list")
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            bad = int(idx.min()) if idx.min() < 0 else int(idx.max())
            raise InputError(f"{rpath}: segment {s.id} index {bad} out of range [0, {n})")
    # Fit4CAD's ground truth has one segment per CAD face: a maximal primitive
    # is scored by its connected parts.
    measures = classification_measures(result.faces(), gt, n)
    return {
        "measures": {k: measures[k] for k in MEASURES},
        "mfe": mfe_stats(result),
        "n_gt": len(gt),
        "n_pred": len(result.segments),
    }
