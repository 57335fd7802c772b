"""Appearance of a scan: colors shaded by a light, per-instance color variation, no color.

Pure numpy. The scanner returns the plain material color of the triangle each ray hit; this
module turns those colors into what a real scanner's camera might deliver, per room:

- shading (probability ``shading``): a directional light from above, tilted by a random angle in
  ``light_tilt`` (degrees) towards a random azimuth; a point's color is scaled by
  ``ambient + (1 - ambient) * max(0, n . l)``, with ``n`` the normal of its hit triangle turned
  towards the sensor position the point was seen from and ``l`` the unit vector to the light;
- instance variation (std ``instance_variation``): every annotated part gets its own color
  factor, a brightness factor shared by the channels times a smaller per-channel tint, so two
  chairs of one asset differ;
- colorless (probability ``colorless``): every color is 0, as scanners without a camera write.

The draws come from a room's own appearance stream and always take the same numbers of values,
so switching one effect changes neither the others nor the layout and the scan.
"""
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from generator.scanner import ScanResult, TriangleScene


@dataclass(frozen=True)
class RoomAppearance:
    """The appearance drawn for one room."""

    shading: bool
    light: np.ndarray  # (3,) unit vector towards the light (drawn even when shading is off)
    ambient: float  # color factor of a face turned away from the light
    colorless: bool
    instance_variation: float
    part_factor: np.ndarray  # (P, 3) color factor per part

    def meta(self) -> dict[str, Any]:
        """The ``generator.appearance`` block of meta.json."""
        return {
            'shading': self.shading,
            'light': np.round(self.light, 6).tolist() if self.shading else None,
            'colorless': self.colorless,
            'instance_variation': self.instance_variation,
        }


def draw_appearance(rng: np.random.Generator, config: Mapping[str, Any],
                    parts: int) -> RoomAppearance:
    """Draw a room's appearance for ``parts`` annotated parts from the ``appearance`` config."""
    shading_drawn = bool(rng.random() < config['shading'])
    colorless = bool(rng.random() < config['colorless'])
    shading = shading_drawn and not colorless  # nothing to shade in a colorless room
    tilt = np.radians(rng.uniform(*config['light_tilt']))
    azimuth = rng.uniform(0.0, 2 * np.pi)
    light = np.array(
        [np.sin(tilt) * np.cos(azimuth),
         np.sin(tilt) * np.sin(azimuth),
         np.cos(tilt)])
    variation = float(config['instance_variation'])
    brightness = rng.standard_normal((parts, 1))
    tint = rng.standard_normal((parts, 3))
    part_factor = np.clip(1.0 + variation * (brightness + 0.5 * tint), 0.0, None)
    return RoomAppearance(shading, light, float(config['ambient']), colorless, variation,
                          part_factor)


def facing_normals(scene: TriangleScene, triangle: np.ndarray, xyz: np.ndarray,
                   origin: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) float32 of the hit triangles, each turned towards its point's sensor."""
    corners = scene.vertices[scene.triangles]  # (T, 3, 3)
    per_triangle = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    per_triangle /= np.maximum(np.linalg.norm(per_triangle, axis=1, keepdims=True), 1e-30)
    normals = np.take(per_triangle.astype(np.float32), triangle, axis=0)
    away = np.einsum('ij,ij->i', normals, origin - xyz.astype(np.float32)) < 0
    normals[away] *= -1
    return normals


def apply_appearance(appearance: RoomAppearance, scan: ScanResult,
                     scene: TriangleScene) -> np.ndarray:
    """The colors (N, 3) uint8 of ``scan`` under ``appearance`` (its own colors when all off)."""
    if appearance.colorless:
        return np.zeros_like(scan.rgb)
    if not appearance.shading and appearance.instance_variation == 0:
        return scan.rgb
    factor = np.take(appearance.part_factor, scan.part, axis=0).astype(np.float32)
    if appearance.shading:
        normals = facing_normals(scene, scan.triangle, scan.xyz, scan.origin)
        lit = np.clip(normals @ appearance.light, 0.0, None)
        factor *= (appearance.ambient + (1.0 - appearance.ambient) * lit)[:, None]
    return np.clip(np.rint(scan.rgb * factor), 0, 255).astype(np.uint8)
