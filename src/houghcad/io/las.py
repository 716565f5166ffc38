"""LAS and LAZ reader [``las``] (laspy, with the lazrs backend for LAZ).

The points are the scaled ``x, y, z``; normals are read from extra dimensions
named ``nx, ny, nz`` or ``normal_x, normal_y, normal_z`` when present; the
other per-point dimensions (intensity, classification, colour, GPS time, extra
bytes ...) are kept as the cloud's ``fields``.
"""

from __future__ import annotations

import io
import logging
import struct
from collections.abc import Callable

import numpy as np

from ..errors import InputError
from .common import Parsed, one_line, pick_normals

_LAS_MAGIC = b"LASF"
#: Dimensions that are not per-point attributes worth keeping (raw integer coordinates).
_SKIP = {"x", "y", "z", "X", "Y", "Z"}
#: Sizes fixed by the LAS specification (bytes): the 1.0-1.2 public header, a VLR header, an
#: EVLR header and the smallest point record (format 0).
_MIN_HEADER, _VLR_HEADER, _EVLR_HEADER, _MIN_RECORD = 227, 54, 60, 20
#: A LAZ body decompresses to at most this many times its size. Arithmetic coding of real scans
#: reaches 5-15x; the bound only stops a damaged count from allocating terabytes.
_MAX_LAZ_RATIO = 200
#: The laszip VLR's fixed part (bytes) before its item list, and its "variable chunks" size.
_LASZIP_FIXED, _VARIABLE_CHUNKS = 34, 0xFFFFFFFF
#: Largest LAZ chunk (points) accepted beyond the point count; LASzip writes 50,000.
_MAX_CHUNK = 1_000_000


class _Caught(logging.Handler):
    """Collects the error messages a library logs while it reads."""

    def __init__(self) -> None:
        super().__init__(level=logging.ERROR)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def is_las(head: bytes, ext: str) -> bool:
    """LAS/LAZ signature: the file starts with ``LASF``."""
    return head.startswith(_LAS_MAGIC)


def read_las(data: bytes, source: str) -> Parsed:
    """LAS 1.0-1.4 or LAZ via laspy: (points, normals or None, fields)."""
    import laspy

    _check_header(data, source)
    # laspy logs a truncated body as an error and returns the points it got: catch the log
    # (it would reach stderr as a second line) and refuse the file.
    caught = _Caught()
    logger = logging.getLogger("laspy")
    logger.addHandler(caught)
    try:
        las = laspy.read(io.BytesIO(data))
        points = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)]).astype(np.float64)
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # laspy raises assorted types; a lazrs panic is a BaseException
        raise InputError(f"{source}: cannot parse LAS/LAZ file ({one_line(exc)})") from None
    finally:
        logger.removeHandler(caught)
    announced = int(las.header.point_count)
    if caught.messages or len(points) != announced:
        why = caught.messages[0] if caught.messages else f"{len(points)} of {announced} points"
        raise InputError(f"{source}: truncated or damaged LAS/LAZ file ({one_line(Exception(why))})")
    columns = {name: np.asarray(las[name]) for name in las.point_format.dimension_names if name not in _SKIP}
    normals, used = pick_normals(columns)
    fields = {name: v for name, v in columns.items()
              if name not in used and v.ndim == 1 and v.dtype.kind in "iufb" and len(v) == len(points)}
    return points, normals, fields


def _check_header(data: bytes, source: str) -> None:
    """Refuse a header whose counts cannot fit in the file.

    laspy trusts the header: a damaged VLR or point count makes it read VLRs or allocate
    points until memory runs out, so the counts are checked against the file size first
    (offsets from the LAS 1.0-1.4 specification)."""
    def bad(why: str) -> InputError:
        return InputError(f"{source}: damaged LAS/LAZ header ({why})")

    size = len(data)
    if not data.startswith(_LAS_MAGIC):
        raise InputError(f"{source}: not a LAS/LAZ file (no LASF signature)")
    if size < _MIN_HEADER:
        raise bad(f"{size} bytes, shorter than a LAS header")
    header_size, offset, n_vlrs = struct.unpack_from("<HII", data, 94)
    point_format, record, legacy_count = struct.unpack_from("<BHI", data, 104)
    minor = data[25]
    count = legacy_count
    if minor >= 4 and size >= 255:
        start_evlr, n_evlrs, count14 = struct.unpack_from("<QIQ", data, 235)
        count = max(count, count14)
        if n_evlrs and (start_evlr > size or n_evlrs * _EVLR_HEADER > size - min(start_evlr, size)):
            raise bad(f"{n_evlrs} extended VLRs announced past the end of the file")
    if not _MIN_HEADER <= header_size <= offset <= size:
        raise bad(f"header size {header_size} and point offset {offset} in a {size}-byte file")
    if n_vlrs * _VLR_HEADER > offset - header_size:
        raise bad(f"{n_vlrs} VLRs announced in {offset - header_size} bytes")
    if record < _MIN_RECORD:
        raise bad(f"point records of {record} bytes")
    body = size - offset
    compressed = bool(point_format & 0xC0)  # LAZ sets bit 7 (and laszip bit 6) of the format id
    room = body * _MAX_LAZ_RATIO if compressed else body
    if count * record > room:
        raise bad(f"{count} points of {record} bytes announced in a {body}-byte body")
    if compressed:
        _check_laszip(data, header_size, n_vlrs, offset, count, record, bad)


def _check_laszip(data: bytes, at: int, n_vlrs: int, offset: int, count: int, record: int,
                  bad: Callable[[str], InputError]) -> None:
    """The LAZ description (laszip VLR) and chunk table must fit the file.

    lazrs allocates what these fields announce and aborts the whole process, uncatchably, when
    an allocation fails; so the chunk size, the items and the number of chunks are bounded
    here (layout from the LASzip specification)."""
    laszip = None
    for _ in range(n_vlrs):
        user, length = data[at + 2:at + 18].rstrip(b"\0"), struct.unpack_from("<H", data, at + 20)[0]
        if at + _VLR_HEADER + length > offset:
            raise bad("a VLR runs into the points")
        if user == b"laszip encoded":
            laszip = (at + _VLR_HEADER, length)
        at += _VLR_HEADER + length
    if laszip is None:
        raise bad("compressed points without a laszip VLR")
    start, length = laszip
    if length < _LASZIP_FIXED:
        raise bad("short laszip VLR")
    chunk, n_items = struct.unpack_from("<I", data, start + 12)[0], struct.unpack_from("<H", data, start + 32)[0]
    if _LASZIP_FIXED + 6 * n_items > length:
        raise bad(f"{n_items} LAZ items in a {length}-byte laszip VLR")
    sizes = struct.unpack_from(f"<{3 * n_items}H", data, start + _LASZIP_FIXED)[1::3]
    if sum(sizes) != record:
        raise bad(f"LAZ items of {sum(sizes)} bytes for {record}-byte points")
    variable = chunk == _VARIABLE_CHUNKS
    if not variable and not 0 < chunk <= max(count, _MAX_CHUNK):
        raise bad(f"LAZ chunks of {chunk} points for {count} points")
    if offset + 8 > len(data):
        raise bad("no LAZ chunk table offset")
    table = struct.unpack_from("<q", data, offset)[0]
    if table == -1:  # no chunk table written: lazrs reads the chunks in sequence
        return
    if not offset + 8 <= table <= len(data) - 8:
        raise bad(f"LAZ chunk table at byte {table} of a {len(data)}-byte file")
    n_chunks = struct.unpack_from("<I", data, table + 4)[0]
    most = max(count, 1) if variable else -(-max(count, 1) // chunk)
    if n_chunks > min(most, len(data) - offset):
        raise bad(f"{n_chunks} LAZ chunks announced for {count} points")
