"""Plain-text summaries of a :class:`houghcad.result.Result`."""

from __future__ import annotations

import math

import numpy as np

from .result import GROUP_KINDS, Result

__all__ = ["summary_table", "groups_table"]

# Families in the order the paper lists them; unknown types follow alphabetically.
_FAMILY_ORDER = ("plane", "cylinder", "cone", "sphere", "torus")
_TOTAL_KEYS = ("total", "total_s", "all")


def _fmt_mfe(value: float) -> str:
    """MFE (dimensionless, typically 1e-4..1e-2) in a fixed 9-character field."""
    return f"{value:9.2e}" if math.isfinite(value) else f"{'-':>9}"


def _mfe_stats(mfe: np.ndarray) -> tuple[float, float]:
    """(mean, max) of the finite values of a 1-D array; NaN when there are none."""
    finite = mfe[np.isfinite(mfe)]
    if finite.size == 0:
        return math.nan, math.nan
    return float(finite.mean()), float(finite.max())


def _family_rows(result: Result) -> list[tuple[str, int, int, float, float]]:
    """(type, segments, points, mean MFE, max MFE) per family present, plus a total row."""
    types = sorted({s.type for s in result.segments},
                   key=lambda t: (_FAMILY_ORDER.index(t) if t in _FAMILY_ORDER else len(_FAMILY_ORDER), t))
    rows = []
    for t in types:
        segs = [s for s in result.segments if s.type == t]
        mfe = np.array([s.mfe for s in segs], dtype=np.float64)
        rows.append((t, len(segs), sum(len(s.indices) for s in segs), *_mfe_stats(mfe)))
    all_mfe = np.array([s.mfe for s in result.segments], dtype=np.float64)
    rows.append(("total", len(result.segments), sum(len(s.indices) for s in result.segments),
                 *_mfe_stats(all_mfe)))
    return rows


def _timing_lines(timing: dict[str, float]) -> list[str]:
    """``time`` lines: the total (given or summed) then each stage, in seconds."""
    stages = {k: float(v) for k, v in timing.items() if k not in _TOTAL_KEYS}
    total = next((float(timing[k]) for k in _TOTAL_KEYS if k in timing), sum(stages.values()))
    width = max([10] + [len(name) for name in stages])  # keep the seconds column aligned
    lines = [f"{'time':<{width + 2}}{total:>10.2f} s"]
    lines += [f"  {name:<{width}}{sec:>10.2f} s" for name, sec in stages.items()]
    return lines


def _fmt_descriptor(value) -> str:
    """A shared descriptor in a few characters: 4 significant digits, vectors in parentheses."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return "(" + ", ".join(_fmt_descriptor(v) for v in value) + ")"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return str(value)
    return f"{float(value):.4g}"


def _fmt_members(members: list[int], limit: int = 6) -> str:
    """Segment ids, the first ``limit`` of them and a count of the rest."""
    shown = ", ".join(str(int(m)) for m in members[:limit])
    return shown + (f", ... (+{len(members) - limit})" if len(members) > limit else "")


_PLURAL = {"sphere": "spheres", "torus": "tori", "annulus": "annuli"}
#: The shape descriptor a sentence names first, per family.
_SHAPE_WORDS = {"plane": ("extent", "size"), "cylinder": ("radius", "radius"), "sphere": ("radius", "radius"), "cone": ("half_angle", "half-angle"),
                "torus": ("major_radius", "radii")}
_HOW = {"translation": "repeated by translation", "rotation": "repeated by rotation",
        "reflection": "mirrored across a plane"}


def _plural(type_name: str, n: int) -> str:
    name = type_name.replace("_", " ")
    return name if n == 1 else _PLURAL.get(type_name, name + "s")


def _shape_value(type_name: str, d: dict, key: str) -> str:
    """The shape descriptor ``d[key]`` in words a reader expects: a plane's size as its two
    lengths in the plane (its extent's first, across the plane, is only rounding on a CAD
    face), a cone's half-angle in degrees, a torus's two radii."""
    v = d[key]
    if type_name == "plane" and isinstance(v, (list, tuple, np.ndarray)) and len(v) == 3:
        return f"{_fmt_descriptor(v[1])} × {_fmt_descriptor(v[2])}"
    if type_name == "cone":
        return f"{float(np.degrees(float(v))):.4g}°"
    if type_name == "torus" and "minor_radius" in d:
        return f"{_fmt_descriptor(v)} and {_fmt_descriptor(d['minor_radius'])}"
    return _fmt_descriptor(v)


def group_sentence(group, result: Result) -> str:
    """A plain-language line for an association group, e.g. "6 cylinders of
    equal radius 2.5, repeated by translation"."""
    n = len(group.members)
    types = sorted({result.segments[m].type for m in group.members if 0 <= m < len(result.segments)})
    t = types[0] if len(types) == 1 else "segment"
    d = group.descriptors
    if group.kind in _HOW:
        key, word = _SHAPE_WORDS.get(t, (None, "shape"))
        shape = f"equal {word} {_shape_value(t, d, key)}" if key in d else "equal shape"
        return f"{n} {_plural(t, n)} of {shape}, {_HOW[group.kind]}"
    if group.kind == "same_primitive":
        parts = d.get("parts")
        if n == 1 and parts:
            return f"one {t.replace('_', ' ')} in {int(parts)} separate parts"
        return f"{n} segments on one {t.replace('_', ' ')}"
    if group.kind == "coaxial":
        return f"{n} {_plural(t, n)} on one axis"
    if group.kind == "parallel":
        what = "normals" if t == "plane" else "axes"
        return f"{n} {_plural(t, n)} with parallel {what}"
    return f"{n} segments ({group.kind})"


def groups_table(result: Result) -> str:
    """Fixed-width text table of the association groups, empty string when there are none.

    One row per group, by kind (:data:`~houghcad.result.GROUP_KINDS` order)
    then id: group id, kind, member segment ids, and what they share in plain
    language (:func:`group_sentence`; world units, 4 significant digits).
    """
    if not result.groups:
        return ""
    order = sorted(range(len(result.groups)), key=lambda i: (
        GROUP_KINDS.index(result.groups[i].kind) if result.groups[i].kind in GROUP_KINDS else len(GROUP_KINDS), i))
    header = f"{'group':<6}{'kind':<16}{'members':<28}what"
    lines = [header, "-" * len(header)]
    for i in order:
        g = result.groups[i]
        # Scalars (radius, angle, count) say most in least room: they go first.
        members = _fmt_members(g.members)
        lines.append(f"{i:<6d}{g.kind:<16}{members:<27} {group_sentence(g, result)}".rstrip())
    return "\n".join(lines)


def summary_table(result: Result) -> str:
    """Fixed-width text table summarising ``result``.

    One row per family present (segments, points, mean and max MFE), a total
    row, the number of unsegmented points (and their share of the cloud) and
    the scales the run derived (noise policy, σ, spacing, τ, ε), the groups
    (:func:`groups_table`) when there are any, and the wall-clock
    time, total then per stage.  No trailing newline.
    """
    rows = _family_rows(result)
    # The first column as wide as the longest family name (generalized_cylinder: 20).
    w = max([12] + [len(r[0]) + 1 for r in rows])
    header = f"{'family':<{w}}{'segments':>9}{'points':>10}{'mean MFE':>11}{'max MFE':>11}"
    lines = [header, "-" * len(header)]
    for i, (name, n_seg, n_pts, mean_mfe, max_mfe) in enumerate(rows):
        if i == len(rows) - 1:
            lines.append("-" * len(header))
        lines.append(f"{name:<{w}}{n_seg:>9d}{n_pts:>10d}  {_fmt_mfe(mean_mfe)}  {_fmt_mfe(max_mfe)}")
    n_unseg = len(result.unsegmented)
    share = 100.0 * n_unseg / result.n_points if result.n_points else 0.0
    lines.append(f"{'unsegmented':<{w}}{'':>9}{n_unseg:>10d}  ({share:.1f}% of {result.n_points} points)")
    derived = result.options.get("derived") if isinstance(result.options, dict) else None
    if derived:
        lines.append(f"{'scales':<{w}}noise {derived['noise_policy']}: sigma {derived['sigma']:.3g}, "
                     f"spacing {derived['spacing']:.3g}, tau {derived['tau']:.3g}, "
                     f"epsilon {derived['epsilon']:.3g} (input units)")
    if result.groups:
        lines.append("")
        lines.append(groups_table(result))
    if result.timing:
        lines.append("")
        lines += _timing_lines(result.timing)
    return "\n".join(lines)
