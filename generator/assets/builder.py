"""bmesh building blocks for the procedural assets.

A :class:`MeshBuilder` collects closed solids (boxes, cylinders, rods, lofts) into one bmesh, each
face tagged with a named material of a plain sRGB color, and turns the result into a bpy object.
Placement uses 4x4 ``mathutils.Matrix`` frames, so kinematic chains compose by multiplication.
"""
from __future__ import annotations

import math
from typing import Collection, Iterable, Sequence

# isort: off
import bpy  # first: importing bpy makes bmesh and mathutils importable
import bmesh
from mathutils import Matrix, Vector
# isort: on

RGB = tuple[int, int, int]
Point = Sequence[float]

IDENTITY = Matrix.Identity(4)


def srgb_to_linear(value: float) -> float:
    """sRGB-encoded channel in [0, 1] -> linear channel (Blender stores linear colors)."""
    if value <= 0.04045:
        return value / 12.92
    return ((value + 0.055) / 1.055)**2.4


def linear_to_srgb(value: float) -> float:
    """Linear channel -> sRGB-encoded channel in [0, 1] (what Blender's color picker shows)."""
    value = min(max(value, 0.0), 1.0)
    if value <= 0.0031308:
        return value * 12.92
    return 1.055 * value**(1.0 / 2.4) - 0.055


def rgb_to_blender(rgb: RGB) -> tuple[float, float, float, float]:
    """uint8 sRGB color -> linear RGBA floats for a material."""
    return (*(srgb_to_linear(c / 255.0) for c in rgb), 1.0)


def blender_to_rgb(rgba: Sequence[float]) -> RGB:
    """Linear material color -> uint8 sRGB color."""
    return tuple(int(round(linear_to_srgb(float(c)) * 255.0)) for c in rgba[:3])


def translate(x: float, y: float, z: float) -> Matrix:
    """Translation matrix."""
    return Matrix.Translation((x, y, z))


def matrix_from_array(array) -> Matrix:
    """4x4 numpy array -> mathutils Matrix."""
    return Matrix([list(map(float, row)) for row in array])


def rot_x(angle: float) -> Matrix:
    """Rotation about the x axis (radians)."""
    return Matrix.Rotation(angle, 4, 'X')


def rot_y(angle: float) -> Matrix:
    """Rotation about the y axis (radians)."""
    return Matrix.Rotation(angle, 4, 'Y')


def rot_z(angle: float) -> Matrix:
    """Rotation about the z axis (radians)."""
    return Matrix.Rotation(angle, 4, 'Z')


def circle(radius: float, segments: int, z: float = 0.0) -> list[tuple[float, float, float]]:
    """Counter-clockwise circle of `segments` points in the plane at height z."""
    return [(radius * math.cos(2 * math.pi * i / segments),
             radius * math.sin(2 * math.pi * i / segments), z) for i in range(segments)]


def rounded_rect(width: float,
                 depth: float,
                 radius: float,
                 corner_segments: int = 4,
                 z: float = 0.0) -> list[tuple[float, float, float]]:
    """Counter-clockwise rectangle centred at the origin with rounded corners."""
    radius = min(radius, 0.5 * width - 1e-4, 0.5 * depth - 1e-4)
    centres = [(0.5 * width - radius, 0.5 * depth - radius),
               (-0.5 * width + radius, 0.5 * depth - radius),
               (-0.5 * width + radius, -0.5 * depth + radius),
               (0.5 * width - radius, -0.5 * depth + radius)]
    points = []
    for corner, (cx, cy) in enumerate(centres):
        for k in range(corner_segments + 1):
            angle = 0.5 * math.pi * (corner + k / corner_segments)
            points.append((cx + radius * math.cos(angle), cy + radius * math.sin(angle), z))
    return points


class MeshBuilder:
    """Accumulates colored closed solids in one bmesh."""

    def __init__(self) -> None:
        self.bm = bmesh.new()
        self._materials: dict[str, int] = {}
        self._colors: list[RGB] = []

    def material(self, name: str, rgb: Sequence[int]) -> int:
        """Register (or look up) a named material with a uint8 sRGB color; returns its index."""
        if name in self._materials:
            return self._materials[name]
        self._materials[name] = len(self._colors)
        self._colors.append(tuple(int(c) for c in rgb))
        return self._materials[name]

    def materials(self, params: dict, **color_keys: str) -> tuple[int, ...]:
        """Register one material per keyword, in order: the keyword names it and its value is the
        key of its color in ``params``; returns their indices."""
        return tuple(self.material(name, params[key]) for name, key in color_keys.items())

    @property
    def colors(self) -> list[RGB]:
        """Material colors in index order."""
        return list(self._colors)

    def _tag(self, verts: Iterable[bmesh.types.BMVert], material: int) -> None:
        for face in {f for v in verts for f in v.link_faces}:
            face.material_index = material

    def box(self, size: Point, material: int, at: Matrix = IDENTITY) -> None:
        """Box of extent `size`, centred at the origin of frame `at`."""
        scale = Matrix.Diagonal((size[0], size[1], size[2], 1.0))
        result = bmesh.ops.create_cube(self.bm, size=1.0, matrix=at @ scale)
        self._tag(result['verts'], material)

    def box_between(self, lo: Point, hi: Point, material: int, at: Matrix = IDENTITY) -> None:
        """Axis-aligned box (in frame `at`) spanning corner `lo` to corner `hi`."""
        centre = [(a + b) / 2 for a, b in zip(lo, hi)]
        size = [abs(b - a) for a, b in zip(lo, hi)]
        self.box(size, material, at @ translate(*centre))

    def cylinder(self,
                 radius: float,
                 height: float,
                 material: int,
                 at: Matrix = IDENTITY,
                 radius_top: float | None = None,
                 segments: int = 16) -> None:
        """Closed cylinder (or frustum) along the frame's z axis, its base at the frame origin."""
        top = radius if radius_top is None else radius_top
        result = bmesh.ops.create_cone(
            self.bm,
            cap_ends=True,
            cap_tris=False,
            segments=segments,
            radius1=radius,
            radius2=top,
            depth=height,
            matrix=at @ translate(0, 0, height / 2))
        self._tag(result['verts'], material)

    def rod(self,
            start: Point,
            end: Point,
            radius: float,
            material: int,
            at: Matrix = IDENTITY,
            segments: int = 12) -> None:
        """Cylinder from point `start` to point `end` (in frame `at`)."""
        start_v, end_v = Vector(start), Vector(end)
        axis = end_v - start_v
        frame = translate(*start_v) @ axis.to_track_quat('Z', 'Y').to_matrix().to_4x4()
        self.cylinder(radius, axis.length, material, at @ frame, segments=segments)

    def bar(self,
            start: Point,
            end: Point,
            width: float,
            thickness: float,
            material: int,
            at: Matrix = IDENTITY) -> None:
        """Square-section bar from `start` to `end`: width along the frame's x-ish side."""
        start_v, end_v = Vector(start), Vector(end)
        axis = end_v - start_v
        frame = (
            translate(*(
                (start_v + end_v) / 2)) @ axis.to_track_quat('Z', 'Y').to_matrix().to_4x4())
        self.box((width, thickness, axis.length), material, at @ frame)

    def loft(self, rings: Sequence[Sequence[Point]], material: int, at: Matrix = IDENTITY) -> None:
        """Closed solid through rings of equally many points, capped at both ends."""
        count = len(rings[0])
        if any(len(ring) != count for ring in rings) or len(rings) < 2:
            raise ValueError('loft needs at least 2 rings of equal length')
        vert_rings = [[self.bm.verts.new(at @ Vector(p)) for p in ring] for ring in rings]
        for lower, upper in zip(vert_rings, vert_rings[1:]):
            for i in range(count):
                j = (i + 1) % count
                self.bm.faces.new((lower[i], lower[j], upper[j], upper[i]))
        self.bm.faces.new(list(reversed(vert_rings[0])))
        self.bm.faces.new(vert_rings[-1])
        self._tag([v for ring in vert_rings for v in ring], material)

    def prism(self,
              outline: Sequence[Point],
              height: float,
              material: int,
              at: Matrix = IDENTITY) -> None:
        """Extrude a counter-clockwise x/y outline from z=0 to z=height in frame `at`."""
        bottom = [(p[0], p[1], 0.0) for p in outline]
        top = [(p[0], p[1], height) for p in outline]
        self.loft([bottom, top], material, at)

    def to_object(self,
                  name: str,
                  collection: bpy.types.Collection,
                  material_prefix: str | None = None) -> bpy.types.Object:
        """Triangulate and store as a new mesh object linked to `collection`."""
        faces = self.bm.faces[:]
        bmesh.ops.recalc_face_normals(self.bm, faces=faces)
        bmesh.ops.triangulate(self.bm, faces=faces)
        mesh = bpy.data.meshes.new(name)
        self.bm.to_mesh(mesh)
        self.bm.free()
        prefix = material_prefix or name
        for part, color in zip(self._materials, self._colors):
            material = bpy.data.materials.new(f'{prefix}.{part}')
            set_material_color(material, color)
            mesh.materials.append(material)
        obj = bpy.data.objects.new(name, mesh)
        collection.objects.link(obj)
        return obj


def set_material_color(material: bpy.types.Material, rgb: RGB) -> None:
    """Set both the viewport color and the Principled BSDF base color."""
    rgba = rgb_to_blender(rgb)
    material.diffuse_color = rgba
    if material.node_tree is not None:
        for node in material.node_tree.nodes:
            if node.type == 'BSDF_PRINCIPLED':
                node.inputs['Base Color'].default_value = rgba


def material_color(material: bpy.types.Material | None, default: RGB = (128, 128, 128)) -> RGB:
    """uint8 sRGB color of a material: an unlinked Principled BSDF base color, else the
    viewport (diffuse) color; `default` for an empty slot."""
    if material is None:
        return default
    if material.node_tree is not None:
        for node in material.node_tree.nodes:
            if node.type == 'BSDF_PRINCIPLED':
                base = node.inputs['Base Color']
                if not base.is_linked:
                    return blender_to_rgb(base.default_value)
    return blender_to_rgb(material.diffuse_color)


def uniform(rng, low: float, high: float, digits: int = 3) -> float:
    """A uniform draw rounded to `digits` decimals (millimetres for lengths), so parameters
    survive a JSON round trip exactly."""
    return round(float(rng.uniform(low, high)), digits)


def pick(rng, options: Sequence):
    """One element of `options`, drawn with `rng`."""
    return options[int(rng.integers(len(options)))]


def check_variant(kind: str, variant: str, known: Collection[str]) -> None:
    """Refuse a ``variant`` of asset class ``kind`` that is not in ``known``."""
    if variant not in known:
        raise ValueError(f'unknown {kind} variant {variant!r}')
