"""The one colour palette and the integer type codes of every picture houghcad makes.

The coloured PLY (:func:`houghcad.io.writers.write_result_ply`), the PNG views
(:mod:`houghcad.render`) and the HTML report (:mod:`houghcad.htmlreport`) all
take their colours from here, so a cylinder is the same green everywhere.

Colours follow the paper's figures: planes red, cylinders green, cones blue,
spheres magenta, tori black; the complex families have their own colours and
unsegmented points are yellow. Each family declares its colour and PLY type
code in its own file (:attr:`houghcad.families.Family.color`, ``type_code``);
the tables here are live views of the registered families. The segments of
one type get distinct shades of the type colour (:func:`segment_colors`),
deterministic in the segment id.
"""

from __future__ import annotations

import colorsys
import functools
from collections.abc import Mapping

import numpy as np

from .families import FamilyTable
from .result import Result

__all__ = ["TYPE_CODES", "TYPE_COLORS", "UNSEGMENTED_COLOR", "OTHER_COLOR", "type_code", "type_color",
           "GROUP_COLORS", "NO_GROUP_COLOR", "group_color", "segment_colors", "point_colors", "point_type_codes", "hex_color", "types_present"]

#: Integer code of each family in the PLY ``type`` field (:attr:`Family.type_code`; -1: unsegmented,
#: 0: a family without a code). A live view of the registered families.
TYPE_CODES: Mapping[str, int] = FamilyTable("type_code")
UNSEGMENTED_CODE = -1
OTHER_CODE = 0

#: Base colour (uint8 RGB) of each family (:attr:`Family.color`); the first shade of a type is
#: exactly this colour. A live view of the registered families.
TYPE_COLORS: Mapping[str, tuple[int, int, int]] = FamilyTable("color")
#: Points no segment explains.
UNSEGMENTED_COLOR: tuple[int, int, int] = (255, 215, 0)  # yellow
#: A family without a colour of its own, or not registered.
OTHER_COLOR: tuple[int, int, int] = (190, 190, 190)  # light grey

#: Colours of the association groups (cycled by group id), distinct from one another;
#: segments in no group are drawn in :data:`NO_GROUP_COLOR`.
GROUP_COLORS: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (23, 190, 207), (188, 189, 34), (127, 127, 127),
)
NO_GROUP_COLOR: tuple[int, int, int] = (215, 215, 215)

# The shades of one type: the base colour, then candidates of other lightness and a
# slightly turned hue, taken in farthest-first order (each the farthest in RGB from
# all taken before), so every shade differs clearly from the previous ones.
_LEVELS = 13
_HUE_TURNS = (0.0, -0.04, 0.04)  # fractions of the colour circle


def type_code(type_name: str) -> int:
    """Integer code of a family name (:data:`TYPE_CODES`; 0 for an unknown family)."""
    return TYPE_CODES.get(type_name, OTHER_CODE)


def type_color(type_name: str) -> tuple[int, int, int]:
    """Base uint8 RGB colour of a family (:data:`OTHER_COLOR` for an unknown one)."""
    return TYPE_COLORS.get(type_name, OTHER_COLOR)


def group_color(group_id: int) -> tuple[int, int, int]:
    """Colour of a group id (:data:`GROUP_COLORS` cycled); -1 (no group) is :data:`NO_GROUP_COLOR`."""
    return NO_GROUP_COLOR if group_id < 0 else GROUP_COLORS[group_id % len(GROUP_COLORS)]


def hex_color(rgb) -> str:
    """``#rrggbb`` of a uint8 RGB triple."""
    r, g, b = (int(c) for c in rgb)
    return f"#{r:02x}{g:02x}{b:02x}"


@functools.lru_cache(maxsize=64)
def _shades(rgb: tuple[int, int, int]) -> np.ndarray:
    """All shades of a base colour, shape (K, 3) uint8, row 0 the base colour itself."""
    h, l, s = colorsys.rgb_to_hls(*(c / 255.0 for c in rgb))
    # Black has no hue: its shades are greys, kept darker than mid-grey.
    lo, hi = (0.12, 0.55) if l < 0.1 else (0.2, 0.8)
    cand = [colorsys.hls_to_rgb((h + turn) % 1.0, level, s)
            for turn in _HUE_TURNS for level in np.linspace(lo, hi, _LEVELS)]
    cand = np.unique(np.rint(np.array(cand) * 255.0).astype(np.int64), axis=0)  # greys: turns coincide
    chosen = [np.array(rgb, dtype=np.int64)]
    dist = np.abs(cand - chosen[0]).sum(axis=1)
    while True:
        j = int(np.argmax(dist))
        if dist[j] < 10:  # the rest look like shades already taken
            break
        chosen.append(cand[j])
        dist = np.minimum(dist, np.abs(cand - cand[j]).sum(axis=1))
    return np.array(chosen, dtype=np.uint8)


def _shade(rgb: tuple[int, int, int], k: int) -> tuple[int, int, int]:
    """The k-th shade (k >= 0) of a base colour, cycling past the last; k = 0 is the base colour."""
    table = _shades(tuple(int(c) for c in rgb))
    return tuple(int(c) for c in table[k % len(table)])


def segment_colors(types: list[str]) -> np.ndarray:
    """Colour of each segment: a shade of its type colour, by its rank among the segments of that type.

    Parameters
    ----------
    types : list of str, length S
        The segments' types in id order.

    Returns
    -------
    ndarray of uint8, shape (S, 3)
        RGB.  Deterministic: depends only on ``types``.
    """
    rank: dict[str, int] = {}
    out = np.zeros((len(types), 3), dtype=np.uint8)
    for i, t in enumerate(types):  # one iteration per segment, not per point
        k = rank.get(t, 0)
        rank[t] = k + 1
        out[i] = _shade(type_color(t), k)
    return out


def types_present(result: Result) -> list[str]:
    """The result's families in :data:`TYPE_CODES` order, unknown ones after them alphabetically."""
    names = {s.type for s in result.segments}
    return sorted(names, key=lambda t: (TYPE_CODES.get(t, 99), t))


def point_colors(result: Result, by: str = "segment") -> np.ndarray:
    """Per-point colours of a result.

    Parameters
    ----------
    result : Result
    by : {"segment", "type"}
        ``"segment"``: each segment in its own shade of its type colour;
        ``"type"``: every segment in its type's base colour.

    Returns
    -------
    ndarray of uint8, shape (n_points, 3)
        RGB; unsegmented points are :data:`UNSEGMENTED_COLOR`.
    """
    types = [s.type for s in result.segments]
    if by == "segment":
        table = segment_colors(types)
    elif by == "type":
        table = np.array([type_color(t) for t in types], dtype=np.uint8).reshape(-1, 3)
    else:
        raise ValueError(f"by must be 'segment' or 'type', not {by!r}")
    # Row S of the lookup table is the unsegmented colour, so label -1 indexes it.
    table = np.vstack([table, np.array(UNSEGMENTED_COLOR, dtype=np.uint8)])
    return table[result.labels()]


def point_type_codes(result: Result) -> np.ndarray:
    """Per-point type code, shape (n_points,), int32 (:data:`TYPE_CODES`, -1 unsegmented)."""
    codes = np.array([type_code(s.type) for s in result.segments] + [UNSEGMENTED_CODE], dtype=np.int32)
    return codes[result.labels()]
