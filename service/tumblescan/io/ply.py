"""Point clouds with per-point times as PLY (binary or ASCII in; binary little-endian out).

The reader parses the header itself and memory-maps the vertex block with a numpy
structured dtype, so any scalar type and property name round-trips, millions of points
read in a fraction of a second, and a header that claims more vertices than the file holds
is caught before any data is touched. Times may be called ``t``, ``timestamp`` or ``time``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import MalformedInputError, MissingTimeError, NonFiniteValueError, TimeOrderError

TIME_NAMES = ("t", "timestamp", "time")
MAX_HEADER_BYTES = 64 * 1024
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_NP_TO_PLY = {
    "i1": "char",
    "u1": "uchar",
    "i2": "short",
    "u2": "ushort",
    "i4": "int",
    "u4": "uint",
    "f4": "float",
    "f8": "double",
}


@dataclass
class TimedCloud:
    """Points with a time each; ``fields`` holds every other per-point property (e.g.
    ``frame``, ``line``, ``intensity``) with its dtype."""

    xyz_m: NDArray[np.float64]
    t_s: NDArray[np.float64]
    fields: dict[str, NDArray[Any]] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass(frozen=True)
class _Header:
    fmt: str
    count: int
    dtype: np.dtype
    offset: int


def read_ply(path: str | os.PathLike[str]) -> TimedCloud:
    """Read a PLY whose ``vertex`` element has ``x, y, z`` and a time property."""
    p = Path(path)
    header = _read_header(p)
    names = header.dtype.names or ()
    for axis in "xyz":
        if axis not in names:
            raise MalformedInputError(f"PLY vertex element has no '{axis}' property", field="file")
    time_name = next((n for n in TIME_NAMES if n in names), None)
    if time_name is None:
        raise MissingTimeError(
            f"PLY has no per-point time property (expected one of {', '.join(TIME_NAMES)}; found {', '.join(names)})",
            field="file",
        )
    data = _read_vertices(p, header)
    xyz = np.column_stack([np.asarray(data[a], dtype=float) for a in "xyz"])
    t = np.asarray(data[time_name], dtype=float)
    if not (np.isfinite(xyz).all() and np.isfinite(t).all()):
        i = int(np.flatnonzero(~(np.isfinite(xyz).all(axis=1) & np.isfinite(t)))[0])
        raise NonFiniteValueError(f"vertex {i} has a NaN or infinite coordinate or time", field="file")
    extra = {n: np.array(data[n]) for n in names if n not in ("x", "y", "z", time_name)}
    cloud = TimedCloud(xyz_m=xyz, t_s=t, fields=extra)
    check_line_times(cloud)
    return cloud


def check_line_times(cloud: TimedCloud) -> None:
    """With ``frame`` and ``line`` indices, times must not decrease with the line in a frame."""
    if "frame" not in cloud.fields or "line" not in cloud.fields:
        return
    frame = cloud.fields["frame"].astype(np.int64)
    line = cloud.fields["line"].astype(np.int64)
    order = np.lexsort((line, frame))
    f, t = frame[order], cloud.t_s[order]
    bad = (f[1:] == f[:-1]) & (t[1:] < t[:-1]) & (line[order][1:] != line[order][:-1])
    if bad.any():
        i = order[int(np.flatnonzero(bad)[0]) + 1]
        raise TimeOrderError(
            f"times out of order within frame {frame[i]}: line {line[i]} is earlier "
            f"(t={cloud.t_s[i]} s) than a previous line",
            field="file",
        )


def write_ply(path: str | os.PathLike[str], cloud: TimedCloud, *, time_name: str = "t") -> None:
    """Write binary little-endian PLY: ``x, y, z, t`` as double, other fields with their dtype."""
    cols: list[tuple[str, np.ndarray]] = [
        ("x", cloud.xyz_m[:, 0]),
        ("y", cloud.xyz_m[:, 1]),
        ("z", cloud.xyz_m[:, 2]),
        (time_name, cloud.t_s),
    ]
    cols += [(name, np.asarray(a)) for name, a in cloud.fields.items()]
    dtype = np.dtype([(name, np.asarray(a).dtype.newbyteorder("<").str.lstrip("<|")) for name, a in cols])
    for name, _ in cols:
        if dtype[name].str[1:] not in _NP_TO_PLY:
            raise MalformedInputError(f"field {name!r} has dtype {dtype[name]} that PLY cannot store", field=name)
    rec = np.empty(len(cloud.t_s), dtype=dtype.newbyteorder("<"))
    for name, a in cols:
        rec[name] = a
    lines = ["ply", "format binary_little_endian 1.0", "comment written by tumblescan", f"element vertex {len(rec)}"]
    lines += [f"property {_NP_TO_PLY[dtype[name].str[1:]]} {name}" for name, _ in cols]
    lines.append("end_header")
    with open(path, "wb") as fh:
        fh.write(("\n".join(lines) + "\n").encode("ascii"))
        fh.write(rec.tobytes())


def _read_header(p: Path) -> _Header:
    with open(p, "rb") as fh:
        head = fh.read(MAX_HEADER_BYTES)
    if not head.startswith(b"ply"):
        raise MalformedInputError("not a PLY file (it does not start with 'ply')", field="file")
    end = head.find(b"end_header")
    if end < 0:
        raise MalformedInputError("PLY header has no end_header line (truncated or not PLY)", field="file")
    offset = head.index(b"\n", end) + 1
    fmt, count, props, before, current = "", -1, [], 0, None
    for raw in head[:end].decode("ascii", errors="replace").splitlines()[1:]:
        parts = raw.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format" and len(parts) >= 2:
            fmt = parts[1]
        elif parts[0] == "element" and len(parts) == 3:
            current = parts[1]
            if current == "vertex":
                count = _int(parts[2])
            elif count < 0:
                before += 1
        elif parts[0] == "property" and current == "vertex":
            if len(parts) != 3 or parts[1] == "list":
                raise MalformedInputError(f"unsupported vertex property line: {raw!r}", field="file")
            if parts[1] not in _PLY_TYPES:
                raise MalformedInputError(f"unknown PLY property type {parts[1]!r}", field="file")
            props.append((parts[2], _PLY_TYPES[parts[1]]))
    if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
        raise MalformedInputError(f"unsupported PLY format {fmt!r}", field="file")
    if count < 0 or not props:
        raise MalformedInputError("PLY has no vertex element with properties", field="file")
    if before:
        raise MalformedInputError("PLY vertex element must come first", field="file")
    if len({n for n, _ in props}) != len(props):
        raise MalformedInputError("PLY vertex properties have duplicate names", field="file")
    order = ">" if fmt == "binary_big_endian" else "<"
    dtype = np.dtype([(n, order + code) for n, code in props])
    return _Header(fmt, count, dtype, offset)


def _int(s: str) -> int:
    try:
        v = int(s)
    except ValueError:
        raise MalformedInputError(f"PLY vertex count {s!r} is not an integer", field="file") from None
    if v < 0:
        raise MalformedInputError("PLY vertex count is negative", field="file")
    return v


def _read_vertices(p: Path, h: _Header) -> np.ndarray:
    if h.fmt == "ascii":
        try:
            # No vertices, no body: loadtxt would warn of empty input and give a 1-row shape.
            rows = (
                np.empty((0, len(h.dtype.names or ())))
                if h.count == 0
                else np.loadtxt(p, skiprows=_header_lines(p), max_rows=h.count, ndmin=2, dtype=float)
            )
        except ValueError as exc:
            raise MalformedInputError(f"ASCII PLY body is malformed: {exc}", field="file") from None
        if rows.shape != (h.count, len(h.dtype.names or ())):
            raise MalformedInputError(
                f"PLY header declares {h.count} vertices of {len(h.dtype.names or ())} values; the body differs",
                field="file",
            )
        out = np.empty(h.count, dtype=h.dtype.newbyteorder("="))
        for i, name in enumerate(h.dtype.names or ()):
            out[name] = rows[:, i]
        return out
    need = h.offset + h.count * h.dtype.itemsize
    size = p.stat().st_size
    if size < need:
        have = (size - h.offset) // h.dtype.itemsize
        raise MalformedInputError(
            f"PLY header declares {h.count} vertices but the file holds only {max(have, 0)} "
            "(truncated or lying header)",
            field="file",
        )
    if h.count == 0:
        return np.empty(0, dtype=h.dtype)
    return np.memmap(p, dtype=h.dtype, mode="r", offset=h.offset, shape=(h.count,))


def _header_lines(p: Path) -> int:
    with open(p, "rb") as fh:
        n = 0
        for line in fh:
            n += 1
            if line.strip() == b"end_header":
                return n
    return n
