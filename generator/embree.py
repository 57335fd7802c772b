"""Embree 4 called from compiled code: triangle scenes and the first hits of ray batches.

The library is the one the ``embreex`` wheel ships (``embreex.libs/libembree4*.so*`` beside the
package), loaded with ctypes; nothing is downloaded or compiled. A numba kernel casts the rays
in packets of 8 with ``rtcIntersect8`` (one reused, 32-byte aligned ``RTCRayHit8`` per call) and
writes each ray's distance and triangle straight into the output arrays: no per-call arrays of
normals and barycentrics as a binding's ``run`` would allocate. The kernel releases the GIL, so
threads can cast slices of one batch at the same time.

The scenes are built in Embree's default mode (no ``RTC_SCENE_FLAG_ROBUST``, default build
quality) from float32 vertices and uint32 triangles; a ray starts at distance 0 and ends at
infinity, with all mask bits set.
"""
import ctypes
import functools
import importlib.util
import weakref
from pathlib import Path
from typing import Callable

import numba
import numpy as np

# values of Embree 4's enums (rtcore_buffer.h, rtcore_common.h, rtcore_geometry.h)
_BUFFER_INDEX, _BUFFER_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_GEOMETRY_TRIANGLE = 0
_ERRORS = {
    1: 'unknown error',
    2: 'invalid argument',
    3: 'invalid operation',
    4: 'out of memory',
    5: 'unsupported CPU',
    6: 'cancelled',
}
# the geometry and primitive id Embree leaves in a ray that hits nothing
_INVALID_ID = 0xFFFFFFFF

# rays in a packet (rtcIntersect8) and 4-byte fields per ray of an RTCRayHit8: the ray's 12
# (origin x3, tnear, direction x3, time, tfar, mask, id, flags), the hit's 9 (Ng x3, u, v,
# primID, geomID, instID[1], instPrimID[1]), rounded up
_LANES = 8
_FIELDS = 24
# the fields of an RTCRayHit8 this module writes or reads, each an array of the 8 lanes
_ORIGIN, _TNEAR, _DIRECTION, _TIME, _TFAR, _MASK, _ID, _FLAGS = 0, 3, 4, 7, 8, 9, 10, 11
_PRIM_ID, _GEOM_ID = 17, 18

_POINTER = ctypes.c_size_t
# rtcIntersect8(const int* valid, RTCScene, RTCRayHit8*, RTCIntersectArguments*)
_INTERSECT8 = ctypes.CFUNCTYPE(None, _POINTER, _POINTER, _POINTER, _POINTER)


class EmbreeError(RuntimeError):
    """The Embree library is missing, cannot be loaded, or refused a scene."""


def library_path() -> Path:
    """The Embree 4 library the installed ``embreex`` wheel ships."""
    spec = importlib.util.find_spec('embreex')
    if spec is None or spec.origin is None:
        raise EmbreeError('the embreex package (which ships the Embree 4 library) is not '
                          'installed: pip install embreex')
    folder = Path(spec.origin).resolve().parent.parent / 'embreex.libs'
    found = sorted(folder.glob('libembree4*.so*'))
    if not found:
        raise EmbreeError(f'{folder}: no libembree4*.so* (the embreex wheel ships Embree 4 there)')
    return found[0]


@functools.cache
def _library() -> tuple[ctypes.CDLL, Path]:
    """The loaded library with the argument and result types of the functions used here."""
    path = library_path()
    try:
        library = ctypes.CDLL(str(path))
    except OSError as error:
        raise EmbreeError(f'{path}: cannot be loaded: {error}') from None
    signatures = {
        'rtcNewDevice': ([ctypes.c_char_p], _POINTER),
        'rtcGetDeviceError': ([_POINTER], ctypes.c_int),
        'rtcReleaseDevice': ([_POINTER], None),
        'rtcNewScene': ([_POINTER], _POINTER),
        'rtcCommitScene': ([_POINTER], None),
        'rtcReleaseScene': ([_POINTER], None),
        'rtcNewGeometry': ([_POINTER, ctypes.c_int], _POINTER),
        'rtcSetSharedGeometryBuffer': ([
            _POINTER, ctypes.c_int, ctypes.c_uint, ctypes.c_int, _POINTER, _POINTER, _POINTER,
            _POINTER
        ], None),
        'rtcCommitGeometry': ([_POINTER], None),
        'rtcAttachGeometry': ([_POINTER, _POINTER], ctypes.c_uint),
        'rtcReleaseGeometry': ([_POINTER], None),
    }
    for name, (arguments, result) in signatures.items():
        function = getattr(library, name)
        function.argtypes, function.restype = arguments, result
    return library, path


@functools.cache
def _intersect8() -> Callable[..., None]:
    """``rtcIntersect8`` as a ctypes function numba's kernels take as an argument."""
    library, _ = _library()
    return _INTERSECT8(ctypes.cast(library.rtcIntersect8, ctypes.c_void_p).value)


def _release(library: ctypes.CDLL, scene: int, device: int) -> None:
    """Release a scene and its device (the scene holds the geometry)."""
    library.rtcReleaseScene(scene)
    library.rtcReleaseDevice(device)


class TriangleMeshScene:
    """An Embree scene of one triangle mesh, ready to cast rays on (:func:`first_hits`).

    ``vertices`` (V, 3) are cast to float32 and ``triangles`` (T, 3) to uint32; Embree reads
    both from this object's arrays (shared buffers), which live as long as the scene. The scene
    and its device are released when the object is collected.
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray):
        vertices, triangles = np.asarray(vertices), np.asarray(triangles)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f'vertices must be (V, 3), not {vertices.shape}')
        if triangles.ndim != 2 or triangles.shape[1] != 3:
            raise ValueError(f'triangles must be (T, 3), not {triangles.shape}')
        if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(vertices)):
            raise ValueError(f'triangles index vertices outside 0..{len(vertices) - 1}')
        library, path = _library()
        # 16 bytes per vertex: Embree reads the last vertex of a shared buffer with one 16-byte
        # load
        self._vertices = np.zeros((len(vertices), 4), dtype=np.float32)
        self._vertices[:, :3] = vertices
        self._triangles = np.ascontiguousarray(triangles, dtype=np.uint32)
        self.triangle_count = len(triangles)
        device = library.rtcNewDevice(None)
        if not device:
            raise EmbreeError(f'{path}: rtcNewDevice failed: '
                              f'{_ERRORS.get(library.rtcGetDeviceError(None), "unknown error")}')
        scene = library.rtcNewScene(device)
        self.handle = scene
        self._finalizer = weakref.finalize(self, _release, library, scene, device)
        # an empty mesh has no geometry: every ray misses
        if len(self._triangles):
            geometry = library.rtcNewGeometry(device, _GEOMETRY_TRIANGLE)
            library.rtcSetSharedGeometryBuffer(geometry, _BUFFER_VERTEX, 0, _FORMAT_FLOAT3,
                                               self._vertices.ctypes.data, 0, 16,
                                               len(self._vertices))
            library.rtcSetSharedGeometryBuffer(geometry, _BUFFER_INDEX, 0, _FORMAT_UINT3,
                                               self._triangles.ctypes.data, 0, 12,
                                               len(self._triangles))
            library.rtcCommitGeometry(geometry)
            library.rtcAttachGeometry(scene, geometry)
            library.rtcReleaseGeometry(geometry)  # the scene keeps it
        library.rtcCommitScene(scene)
        error = library.rtcGetDeviceError(device)
        if error:
            self._finalizer()
            raise EmbreeError(f'{path}: building a scene of {len(self._triangles)} triangles '
                              f'failed: {_ERRORS.get(error, f"error {error}")}')


@numba.njit(cache=True, nogil=True)
def _cast_packets(intersect8, scene: int, origins: np.ndarray, directions: np.ndarray,
                  t_hit: np.ndarray, primitive: np.ndarray) -> None:
    """Cast rays ``origins`` + t ``directions`` in packets of 8 consecutive ones: the first
    hit's distance into ``t_hit`` (inf for a miss) and its triangle into ``primitive`` (-1)."""
    block = np.empty(_FIELDS * _LANES + _LANES, dtype=np.float32)
    # the packet starts at the first 32-byte boundary in the block
    start = (-(block.ctypes.data // 4)) % _LANES
    packet = block[start:start + _FIELDS * _LANES]
    words = packet.view(np.uint32)
    valid = np.zeros(_LANES, dtype=np.int32)
    packet_address, valid_address = packet.ctypes.data, valid.ctypes.data
    # the fields Embree only reads, the same for every ray
    for lane in range(_LANES):
        packet[_TNEAR * _LANES + lane] = 0.0
        packet[_TIME * _LANES + lane] = 0.0
        words[_MASK * _LANES + lane] = _INVALID_ID  # all mask bits set
        words[_ID * _LANES + lane] = 0
        words[_FLAGS * _LANES + lane] = 0
    count = len(origins)
    for first in range(0, count, _LANES):
        lanes = min(_LANES, count - first)
        for lane in range(_LANES):
            # a lane past the end repeats the packet's first ray, switched off in ``valid``
            ray = first + lane if lane < lanes else first
            valid[lane] = -1 if lane < lanes else 0
            for axis in range(3):
                packet[(_ORIGIN + axis) * _LANES + lane] = origins[ray, axis]
                packet[(_DIRECTION + axis) * _LANES + lane] = directions[ray, axis]
            packet[_TFAR * _LANES + lane] = np.inf
            words[_GEOM_ID * _LANES + lane] = _INVALID_ID  # stays so on a miss
        intersect8(valid_address, scene, packet_address, 0)
        for lane in range(lanes):
            t_hit[first + lane] = packet[_TFAR * _LANES + lane]
            hit = words[_GEOM_ID * _LANES + lane] != _INVALID_ID
            primitive[first + lane] = np.int32(words[_PRIM_ID * _LANES + lane]) if hit else -1


def first_hits(scene: TriangleMeshScene,
               origins: np.ndarray,
               directions: np.ndarray,
               t_hit: np.ndarray | None = None,
               primitive: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """First hits of rays ``origins`` + t ``directions`` (N, 3, cast to float32) on ``scene``:
    the distance t (float32, in units of the direction's length; inf for a miss) and the
    triangle (int32; -1 for a miss), written into ``t_hit`` and ``primitive`` (N) when given.

    Each ray is cast on its own terms (the packets only group them), so a ray's hit does not
    depend on the batch it is cast in; the GIL is released while casting.
    """
    origins = np.asarray(origins, dtype=np.float32)
    directions = np.asarray(directions, dtype=np.float32)
    if origins.ndim != 2 or origins.shape[1] != 3 or directions.shape != origins.shape:
        raise ValueError(f'origins and directions must both be (N, 3), not {origins.shape} and '
                         f'{directions.shape}')
    count = len(origins)
    if t_hit is None:
        t_hit = np.empty(count, dtype=np.float32)
    if primitive is None:
        primitive = np.empty(count, dtype=np.int32)
    if (t_hit.shape != (count,) or t_hit.dtype != np.float32 or primitive.shape != (count,) or
            primitive.dtype != np.int32):
        raise ValueError(f'the outputs must be float32 and int32 arrays of {count} rays, not '
                         f'{t_hit.dtype} {t_hit.shape} and {primitive.dtype} {primitive.shape}')
    if count and scene.triangle_count:
        _cast_packets(_intersect8(), scene.handle, origins, directions, t_hit, primitive)
    else:
        t_hit.fill(np.inf)
        primitive.fill(-1)
    return t_hit, primitive
