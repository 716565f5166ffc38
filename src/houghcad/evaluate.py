"""Evaluation against Fit4CAD ground truth: classification measures, parameter errors, files.

The ground-truth readers live in :mod:`houghcad.groundtruth` (file formats and the block
correspondence are described there) and are re-exported here: ``read_fit4cad_segments``,
``read_fit4cad_types``, ``read_fit4cad_parameters``.

The classification measures follow the README's definitions; see :func:`classification_measures`.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp

from .errors import InputError
from .groundtruth import (
    read_fit4cad_parameters,
    read_fit4cad_segments,
    read_fit4cad_types,
    read_text,
    unit,
)
from .io import read_points
from .io.readers import FORMAT_TABLE
from .result import Result, check_header

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


class _Confusion(NamedTuple):
    """Counts of each ground-truth segment G against its matched prediction P, shapes (n_gt,)."""

    tp: np.ndarray  # |G n P|, int64
    fp: np.ndarray  # |P n U| - TP
    fn: np.ndarray  # |G| - TP
    tn: np.ndarray  # |U| - TP - FP - FN
    match: np.ndarray  # index of P, -1 when G shares no point with any prediction
    size_g: np.ndarray  # |G|
    p_size: np.ndarray  # |P|, points outside U included (0 when unmatched)
    size_u: int  # |U|, points in some GT segment


def _confusion(G: sp.csr_matrix, P: sp.csr_matrix) -> _Confusion:
    """Match each GT segment (rows of G) with a prediction (rows of P) and count; see
    :func:`classification_measures` for the rules."""
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
    return _Confusion(tp, fp, fn, tn, match, size_g, p_size, size_u)


def _rates(c: _Confusion) -> dict[str, np.ndarray]:
    """The six measures of each GT segment, float64 arrays of shape (n_gt,)."""
    tp, fp, fn, tn = c.tp, c.fp, c.fn, c.tn
    return {
        "DSC": _ratio(2.0 * tp, (c.size_g + c.p_size).astype(np.float64), 0.0),
        "PPV": _ratio(tp.astype(np.float64), (tp + fp).astype(np.float64), 0.0),
        "TPR": _ratio(tp.astype(np.float64), (tp + fn).astype(np.float64), 0.0),
        "TNR": _ratio(tn.astype(np.float64), (tn + fp).astype(np.float64), 1.0),
        "NPV": _ratio(tn.astype(np.float64), (tn + fn).astype(np.float64), 1.0),
        "ACC": _ratio((tp + tn).astype(np.float64), np.full(len(tp), float(c.size_u)), 0.0),
    }


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
    c = _confusion(G, P)
    per = _rates(c)
    n_gt = len(c.tp)
    out: dict[str, Any] = {k: (float(v.mean()) if n_gt else float("nan")) for k, v in per.items()}
    if per_segment:
        out["per_segment"] = {
            **per,
            "TP": c.tp.astype(np.int64),
            "FP": c.fp.astype(np.int64),
            "FN": c.fn.astype(np.int64),
            "TN": c.tn.astype(np.int64),
            "match": c.match.astype(np.int64),
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
    c = float(unit(np.asarray(a, float)) @ unit(np.asarray(b, float)))
    return float(np.degrees(np.arccos(np.clip(c if oriented else abs(c), -1.0, 1.0))))


def _axis_line_distance(truth: dict, found: dict, points: np.ndarray) -> float:
    """Largest distance from the true axis line to the found one over the object's extent (the
    true axis points at both ends of the points' projection onto it)."""
    a, p = unit(np.asarray(truth["axis"], float)), np.asarray(truth["axis_point"], float)
    d, q = unit(np.asarray(found["axis"], float)), np.asarray(found["axis_point"], float)
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
                "offset": abs(float(unit(v(found["normal"])) @ v(truth["point"])) - float(found["offset"]))
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
_CLOUD_EXTENSIONS = tuple(ext for f in FORMAT_TABLE for ext in f.extensions)
#: Files beside a cloud that are its ground truth, not the cloud.
_GT_SUFFIXES = ("_primitives.txt", "_implicit.txt", "_parametric.txt")


def ground_truth_for(path: str | Path) -> Path:
    """Locate the ``_primitives.txt`` ground truth for a point cloud.

    Accepts ``NAME_primitives.txt`` itself, the cloud ``NAME.<ext>`` for any point-cloud
    extension houghcad reads (``.ply .xyz .txt .csv .pts .asc .npy .obj .off .stl .las .laz .e57 .pcd``, any case),
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


def _cloud_beside(given: Path, gt_file: Path) -> Path | None:
    """The point cloud the ground truth belongs to: ``given`` when it is a cloud
    file, else ``NAME.<ext>`` beside ``NAME_primitives.txt``; None when there is none."""
    stem = gt_file.name[: -len("_primitives.txt")]
    names = [given] if given.is_file() and not given.name.endswith(_GT_SUFFIXES) else []
    names += [gt_file.with_name(stem + ext) for ext in _CLOUD_EXTENSIONS]
    return next((p for p in names if p.is_file()), None)


def _warn_other_cloud(source: str | None, gt_file: Path, rpath: Path) -> None:
    """Warn when the result names a cloud other than the ground truth's: two clouds of one point
    count score each other without complaint otherwise (DSC 0.22 for one Fit4CAD cloud on another)."""
    if not source:
        return
    mine, theirs = Path(source).stem, Path(gt_file).name.removesuffix("_primitives.txt")
    if mine != theirs:
        import warnings

        from .errors import InputWarning

        warnings.warn(f"{rpath}: the result is of {Path(source).name}, the ground truth of {theirs}: "
                      "scored as given", InputWarning, stacklevel=3)


def _input(result: Result) -> dict[str, Any]:
    """The result's record of which rows of its file it read (``options["input"]``)."""
    inp = result.options.get("input")
    return inp if isinstance(inp, dict) else {}


def in_file_rows(result: Result) -> Result:
    """``result`` with its points numbered as the rows of its input file, which a ground truth
    numbers: a run that left rows out (``--drop-invalid``, an E57's flagged rows; recorded in
    ``options["input"]["dropped_rows"]``) numbers its points without them. The rows left out
    are unsegmented. ``result`` itself when it left none out; ValueError when the record does not
    match the result's points."""
    ranges = np.asarray(_input(result).get("dropped_rows") or [], dtype=np.int64).reshape(-1, 2)
    if not len(ranges):
        return result
    total = result.n_points + int((ranges[:, 1] - ranges[:, 0]).sum())
    if ranges.min() < 0 or ranges.max() > total or np.any(ranges[:, 1] < ranges[:, 0]):
        raise ValueError("options.input.dropped_rows do not fit the result's points")
    edge = np.zeros(total + 1, np.int64)  # +1 where a range starts, -1 where it stops
    np.add.at(edge, ranges[:, 0], 1)
    np.add.at(edge, ranges[:, 1], -1)
    left_out = np.cumsum(edge)[:-1] > 0
    rows = np.flatnonzero(~left_out)
    if len(rows) != result.n_points:
        raise ValueError("options.input.dropped_rows overlap")
    segments = [replace(s, indices=rows[s.indices], edges=rows[s.edges],
                        parts=[replace(p, indices=rows[p.indices], edges=rows[p.edges]) for p in s.parts])
                for s in result.segments]
    unsegmented = np.sort(np.concatenate([rows[result.unsegmented], np.flatnonzero(left_out)]))
    return replace(result, n_points=total, segments=segments, unsegmented=unsegmented)


def _read_result(rpath: Path) -> Result:
    """The result saved at ``rpath``, checked (:meth:`Result.from_dict`) and in its file's rows
    (:func:`in_file_rows`); InputError naming the file otherwise."""
    text = read_text(rpath)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{rpath}: malformed JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(data, dict):
        raise InputError(f"{rpath}: expected a JSON object, got {type(data).__name__}")
    try:  # the format before the keys: another tool's JSON is named as such
        check_header(data)
    except ValueError as exc:
        raise InputError(f"{rpath}: {exc}") from None
    for key in ("n_points", "segments"):
        if key not in data:
            raise InputError(f"{rpath}: missing key {key!r}")
    try:
        return in_file_rows(Result.from_dict(data))
    except KeyError as exc:
        raise InputError(f"{rpath}: a segment lacks key {exc.args[0]!r}") from None
    except (TypeError, ValueError, OverflowError) as exc:  # OverflowError: an index past int64
        raise InputError(f"{rpath}: invalid result ({exc})") from None


def evaluate_files(result_json_path: str | Path, ground_truth_path: str | Path,
                   maximal: bool = False) -> dict[str, Any]:
    """Evaluate a saved :class:`Result` (JSON of ``Result.to_dict()``) against Fit4CAD ground truth.

    Parameters
    ----------
    result_json_path : str or Path
        JSON file written from ``Result.to_dict()``.
    ground_truth_path : str or Path
        Anything :func:`ground_truth_for` accepts.
    maximal : bool
        Score the maximal primitives (the JSON's segments) instead of their faces (each
        segment's connected parts, the unit of Fit4CAD's ground truth).

    Returns
    -------
    dict
        ``{"measures": {"DSC", "PPV", "TPR", "TNR", "NPV", "ACC"}, "mfe": {"min", "mean", "max"},
        "scored": "faces" | "maximal", "n_gt": int, "n_pred": int}``; ``n_pred`` counts what
        was scored.
    """
    rpath = Path(result_json_path)
    result = _read_result(rpath)
    gt_file = ground_truth_for(ground_truth_path)
    gt = read_fit4cad_segments(gt_file)
    n = result.n_points
    _warn_other_cloud(result.source, gt_file, rpath)
    cloud = _cloud_beside(Path(ground_truth_path), gt_file)
    if cloud is not None:
        # Its rows, those the run left out included (the ground truth numbers them all).
        m = read_points(cloud, drop_invalid=bool(_input(result).get("drop_invalid"))).provenance()["rows"]
        if m != n:
            raise InputError(f"{rpath}: the result has {n} points but the cloud {cloud.name} has {m}: "
                             "not a result of this cloud")
    gt_max = max((int(g.max()) for g in gt if g.size), default=-1)
    if gt_max >= n:
        raise InputError(
            f"{gt_file}: index {gt_max + 1} (1-based) exceeds the result's n_points {n}"
        )
    # Fit4CAD's ground truth has one segment per CAD face: by default a
    # maximal primitive is scored by its connected parts.
    pred = [s.with_edges() for s in result.segments] if maximal else result.faces()
    measures = classification_measures(pred, gt, n)
    return {
        "measures": {k: measures[k] for k in MEASURES},
        "mfe": mfe_stats(result),
        "scored": "maximal" if maximal else "faces",
        "n_gt": len(gt),
        "n_pred": len(pred),
    }
