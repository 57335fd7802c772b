"""Sensor models on the Embree caster, one drawn per room: the paper's crossing path
(:mod:`generator.scanner`), a terrestrial laser scanner (:mod:`generator.tls`), a handheld
tablet LiDAR (:mod:`generator.tablet`), one RGB-D depth frame (:mod:`generator.depth_frame`) and
a fused RGB-D reconstruction (:mod:`generator.reconstruction`); here the draw, the dispatch to
the model and the annotation of stray returns.

Every model builds ray batches (origins, directions) and casts them through
:meth:`generator.scanner.Scanner.cast`, the one place rays are cast. The paper model is
:meth:`Scanner.scan` on :func:`generator.scanner.sensor_path` (object-ratio phase, uniform or
aimed directions). The other models have no object-ratio phase: the share of object points is
what the geometry gives. What they share (the room's geometry, the grid cast, depth edges, the
labelled result) is in :mod:`generator.sensor_common`.
"""
from typing import Any, Callable, Mapping, NamedTuple, Sequence

import numpy as np

from generator.depth_frame import cast_depth_frame, depth_frame_camera
from generator.reconstruction import scan_reconstruction
from generator.scanner import ScanResult, Scanner, sensor_path
from generator.sensor_common import RoomGeometry
from generator.tablet import cast_tablet, tablet_trajectory
from generator.tls import scan_tls, tls_stations
from synthdet.contracts import SENSOR_MODELS


# the parameters a tablet walk's meta.json record repeats (the tablet's and the reconstruction's)
_WALK_RECORD = ('wall_look', 'fov_deg', 'min_range', 'max_range', 'range_noise', 'far_keep',
                'dark_luminance', 'dark_dropout', 'shiny_dropout')


def choose_sensor(probabilities: Mapping[str, float], rng: np.random.Generator) -> str:
    """Draw one sensor model from ``probabilities`` (model -> probability, summing to 1)."""
    weights = np.array([float(probabilities.get(m, 0.0)) for m in SENSOR_MODELS])
    return SENSOR_MODELS[int(rng.choice(len(SENSOR_MODELS), p=weights / weights.sum()))]


def scan_room(
    scanner: Scanner,
    room: RoomGeometry,
    model: str,
    n_points: int,
    object_ratio: float,
    rng: np.random.Generator,
    scanner_config: Mapping[str, Any],
    shiny_colors: Sequence[Sequence[int]] = ()
) -> tuple[ScanResult, dict[str, Any]]:
    """Scan ``room`` with sensor ``model``; return the points and the sensor's meta.json record.

    ``object_ratio`` applies to the paper model only; ``shiny_colors`` (RGB triples) mark the
    triangles the tablet loses returns on as shiny.
    """
    if model not in _SENSOR_SCANS:
        raise ValueError(f'unknown sensor model {model!r} (known: {", ".join(SENSOR_MODELS)})')
    request = _ScanRequest(scanner, room, n_points, object_ratio, rng, scanner_config,
                           shiny_colors)
    return _SENSOR_SCANS[model](request)


class _ScanRequest(NamedTuple):
    """The arguments of :func:`scan_room` that every sensor model reads from."""

    scanner: Scanner
    room: RoomGeometry
    n_points: int
    object_ratio: float
    rng: np.random.Generator
    scanner_config: Mapping[str, Any]
    shiny_colors: Sequence[Sequence[int]]


def _scan_paper(request: _ScanRequest) -> tuple[ScanResult, dict[str, Any]]:
    """The paper's crossing path: a cross per room or hall bay, with as many sensor positions
    per bay as a room."""
    cfg, room, rng = request.scanner_config, request.room, request.rng
    path, segments = sensor_path(room.polygon, room.height, rng, cfg['path_coverage'],
                                 cfg['sensor_height'],
                                 cfg['path_steps'] * max(1, len(room.bays)), room.cells)
    scan = request.scanner.scan(path, request.n_points, request.object_ratio, rng, cfg)
    return scan, {
        'model': 'paper',
        'path': np.round(segments, 6).tolist(),
        'height': round(cfg['sensor_height'] * room.height, 6),
        **{
            k: cfg[k]
            for k in ('aim_at_objects', 'range_noise', 'angular_jitter', 'dropout')
        }
    }


def _scan_tls(request: _ScanRequest) -> tuple[ScanResult, dict[str, Any]]:
    """A terrestrial laser scanner's stations and their merged, thinned returns."""
    cfg, scanner = request.scanner_config['tls'], request.scanner
    stations = tls_stations(request.room, request.rng, cfg)
    scan, step = scan_tls(scanner, stations, request.n_points, request.rng, cfg,
                          request.scanner_config['batch_rays'],
                          request.room.object_parts[scanner.scene.part])
    return scan, {
        'model': 'tls',
        'stations': np.round(stations, 6).tolist(),
        'angular_step_deg': step,
        **{
            k: cfg[k]
            for k in ('min_elevation_deg', 'min_range', 'max_range', 'range_noise',
                      'mixed_pixels', 'edge_jump', 'oversample', 'point_spacing')
        }
    }


def _scan_tablet(request: _ScanRequest) -> tuple[ScanResult, dict[str, Any]]:
    """A handheld tablet LiDAR's walk through the room."""
    cfg = request.scanner_config['tablet']
    positions, look = tablet_trajectory(request.room, request.rng, cfg)
    scan, _ = cast_tablet(request.scanner, positions, look, request.n_points, request.rng, cfg,
                          request.scanner_config['batch_rays'], request.shiny_colors)
    return scan, {
        'model': 'tablet',
        'trajectory': np.round(positions, 3).tolist(),
        **{k: cfg[k] for k in _WALK_RECORD}
    }


def _scan_depth_frame(request: _ScanRequest) -> tuple[ScanResult, dict[str, Any]]:
    """One RGB-D depth frame of the room."""
    cfg = request.scanner_config['depth_frame']
    camera = depth_frame_camera(request.room, request.rng, cfg)
    scan, record = cast_depth_frame(request.scanner, camera, request.n_points, request.rng, cfg,
                                    request.scanner_config['batch_rays'],
                                    request.room.object_parts, request.shiny_colors)
    return scan, {
        'model': 'depth_frame',
        **record,
        **{
            k: cfg[k]
            for k in ('min_range', 'depth_noise', 'edge_jump', 'edge_dropout', 'dark_luminance',
                      'dark_dropout', 'shiny_dropout', 'min_object_points')
        }
    }


def _scan_reconstruction(request: _ScanRequest) -> tuple[ScanResult, dict[str, Any]]:
    """A fused RGB-D reconstruction of a tablet walk."""
    cfg = request.scanner_config['reconstruction']
    scan, record = scan_reconstruction(request.scanner, request.room, request.n_points,
                                       request.rng, cfg, request.scanner_config['batch_rays'],
                                       request.shiny_colors)
    return scan, {
        'model': 'reconstruction',
        **record,
        **{
            k: cfg[k]
            for k in (*_WALK_RECORD, 'oversample', 'surface_spacing', 'ceiling_keep')
        }
    }


# the scan of each sensor model (every model of synthdet.contracts.SENSOR_MODELS)
_SENSOR_SCANS: dict[str, Callable[[_ScanRequest], tuple[ScanResult, dict[str, Any]]]] = {
    'paper': _scan_paper,
    'tls': _scan_tls,
    'tablet': _scan_tablet,
    'depth_frame': _scan_depth_frame,
    'reconstruction': _scan_reconstruction,
}


def label_stray_returns(part: np.ndarray, names: Sequence[str],
                        stray: np.ndarray | None) -> tuple[np.ndarray, list[str], str | None]:
    """Annotation labels (``part`` indexes ``names``) with the stray returns as one new clutter
    instance, named after the room's other clutter (``clutter_<k>``); returns the labels, the
    names and the new instance's name (None and the inputs unchanged without stray returns)."""
    names = list(names)
    if stray is None or not stray.any():
        return part, names, None
    numbers = [int(n.rsplit('_', 1)[1]) for n in names if n.rsplit('_', 1)[0] == 'clutter']
    name = f'clutter_{max(numbers, default=0) + 1}'
    names.append(name)
    part = part.copy()
    part[stray] = len(names) - 1
    return part, names, name
