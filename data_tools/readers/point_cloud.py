"""The vertices of a PLY point cloud (nerfstudio's ``ply_file_path``, e.g. ``sparse_pc.ply``): ASCII or binary
little-endian, ``x y z`` of the first element, ``vertex``; other properties and elements are skipped."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sray.data_tools.readers.common import read_file

PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
"""PLY scalar type -> NumPy type code (little-endian added where binary)."""


def read_ply_points(path: Path) -> np.ndarray:
    """float64 (P, 3) vertex positions of a PLY file; ValueError naming the file and what is unsupported."""
    path = Path(path)
    data = read_file(path, "missing (named by transforms.json's ply_file_path)")
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError(f"{path}: not a PLY file (no 'ply' magic or no end_header)")
    header = data[:end].decode("ascii", "replace").splitlines()
    body = data[end + len(b"end_header\n"):]
    form = next((line.split()[1] for line in header if line.startswith("format")), "")
    elements = [line.split() for line in header if line.startswith(("element", "property"))]
    if not elements or elements[0][:2] != ["element", "vertex"]:
        raise ValueError(f"{path}: the first PLY element must be 'vertex'")
    count, props = int(elements[0][2]), []
    for words in elements[1:]:
        if words[0] == "element":
            break
        if words[1] == "list" or words[1] not in PLY_TYPES:
            raise ValueError(f"{path}: vertex property {' '.join(words[1:])!r} is not a scalar PLY type")
        props.append((words[2], PLY_TYPES[words[1]]))
    if not {"x", "y", "z"} <= {n for n, _ in props}:
        raise ValueError(f"{path}: vertices need properties x, y and z, got {[n for n, _ in props]}")
    if form == "ascii":
        rows = [line.split() for line in body.decode("ascii").splitlines()[:count]]
        table = np.array(rows, dtype=np.float64).reshape(count, len(props))
        columns = {n: table[:, i] for i, (n, _) in enumerate(props)}
    elif form == "binary_little_endian":
        dtype = np.dtype([(n, "<" + t) for n, t in props])
        if len(body) < count * dtype.itemsize:
            raise ValueError(f"{path}: {count} vertices announced but the file is shorter (truncated?)")
        columns = np.frombuffer(body, dtype=dtype, count=count)
    else:
        raise ValueError(f"{path}: PLY format {form!r} is not supported; write ascii or binary_little_endian")
    return np.stack([np.asarray(columns[a], np.float64) for a in "xyz"], axis=1)
