"""PLY files on ``plyfile``: the project's one PLY writer and its vertex reader."""
from __future__ import annotations

import os
from typing import Mapping, Sequence

import numpy as np

from synthdet.outputs import replaced_file


def write_ply(path: str | os.PathLike,
              vertex: Mapping[str, np.ndarray],
              comments: Sequence[str] = ()) -> None:
    """Write a binary little-endian PLY whose ``vertex`` element has one property per entry of
    ``vertex`` (name -> 1D array; the arrays' dtypes become the property types, in order).

    The file is written through a checked temporary file beside ``path``, renamed into place
    (``synthdet.outputs``).
    """
    from plyfile import PlyData, PlyElement
    columns = {name: np.asarray(values) for name, values in vertex.items()}
    lengths = {len(values) for values in columns.values()}
    if len(lengths) != 1:
        raise ValueError(f'{path}: vertex properties of different lengths {sorted(lengths)}')
    table = np.empty(
        lengths.pop(),
        dtype=[(name, values.dtype.newbyteorder('<')) for name, values in columns.items()])
    for name, values in columns.items():
        table[name] = values
    with replaced_file(path) as stream:
        PlyData([PlyElement.describe(table, 'vertex')], byte_order='<',
                comments=list(comments)).write(stream)


def read_ply_vertices(path: str | os.PathLike) -> np.ndarray:
    """The ``vertex`` element of a PLY file as a structured array; ``ValueError`` naming the
    file when it is not a readable PLY or has no vertices."""
    from plyfile import PlyData
    path = os.fspath(path)
    try:
        ply = PlyData.read(path)
    except Exception as error:  # plyfile raises several types for broken headers and bodies
        raise ValueError(f'{path}: not a readable PLY file ({error})') from None
    if 'vertex' not in ply:
        raise ValueError(f'{path}: PLY file has no vertex element')
    return ply['vertex'].data
