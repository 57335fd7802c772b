"""Blender scene of a room: the layout built as bpy objects, exported as labelled triangle arrays.

Every annotated element (an asset instance, a clutter object, the floor, a wall, ...) becomes one
bpy mesh object in the collection ``synthdet_room``, placed by its transform and tagged with the
custom properties ``synthdet_instance`` and ``synthdet_class``; face colors live in the integer
face attribute ``synthdet_rgb`` (0xRRGGBB; exact) and in the color attribute ``Col`` for display.
Meshes of assets are shared between objects and rooms (linked duplicates). :func:`export_triangles`
reads the scene back - world vertices from each object's ``matrix_world`` - so what is scanned is
what the saved ``.blend`` shows.
"""
from pathlib import Path
from typing import Callable, Sequence

import bpy
import numpy as np

from generator.household import is_procedural, procedural_mesh
from generator.layout import RoomLayout
from generator.scanner import TriangleScene
from generator.structure import structure_parts

COLLECTION = 'synthdet_room'
MeshSource = Callable[[str, str], tuple[np.ndarray, np.ndarray, np.ndarray]]


def mesh_from_arrays(name: str, vertices: np.ndarray, triangles: np.ndarray,
                     colors: np.ndarray) -> bpy.types.Mesh:
    """A bpy mesh from triangle arrays, with exact per-face colors."""
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(vertices))
    mesh.vertices.foreach_set('co', np.asarray(vertices, dtype=np.float32).ravel())
    mesh.loops.add(3 * len(triangles))
    mesh.loops.foreach_set('vertex_index', np.asarray(triangles, dtype=np.int32).ravel())
    mesh.polygons.add(len(triangles))
    mesh.polygons.foreach_set('loop_start', np.arange(0, 3 * len(triangles), 3, dtype=np.int32))
    mesh.update(calc_edges=True)
    rgb = np.asarray(colors, dtype=np.int64)
    packed = mesh.attributes.new('synthdet_rgb', 'INT', 'FACE')
    packed.data.foreach_set('value',
                            ((rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]).astype(np.int32))
    display = mesh.attributes.new('Col', 'BYTE_COLOR', 'FACE')
    rgba = np.concatenate([rgb / 255.0, np.ones((len(rgb), 1))], axis=1).astype(np.float32)
    display.data.foreach_set('color_srgb', rgba.ravel())
    return mesh


class RoomScene:
    """Builds rooms in the current bpy file; asset meshes are created once and reused."""

    def __init__(self, mesh_source: MeshSource):
        """``mesh_source(cls, name)`` returns an asset's local (vertices, triangles, colors)."""
        self.mesh_source = mesh_source
        self._asset_meshes: dict[str, bpy.types.Mesh] = {}
        self.collection = bpy.data.collections.get(COLLECTION)
        if self.collection is None:
            self.collection = bpy.data.collections.new(COLLECTION)
            bpy.context.scene.collection.children.link(self.collection)

    def clear(self) -> None:
        """Remove the previous room's objects and its own (non-asset) meshes."""
        own = {m.name for m in self._asset_meshes.values()}
        for obj in list(self.collection.objects):
            mesh = obj.data
            bpy.data.objects.remove(obj, do_unlink=True)
            if mesh is not None and mesh.name not in own and mesh.users == 0:
                bpy.data.meshes.remove(mesh)

    def _asset_mesh(self, cls: str, name: str) -> bpy.types.Mesh:
        key = f'{cls}/{name}'
        if key not in self._asset_meshes:
            self._asset_meshes[key] = mesh_from_arrays(f'asset:{key}',
                                                       *self.mesh_source(cls, name))
        return self._asset_meshes[key]

    def _add_object(self,
                    name: str,
                    cls: str,
                    mesh: bpy.types.Mesh,
                    location=(0.0, 0.0, 0.0),
                    yaw: float = 0.0) -> bpy.types.Object:
        obj = bpy.data.objects.new(name, mesh)
        obj.location = tuple(float(v) for v in location)
        obj.rotation_euler = (0.0, 0.0, float(yaw))
        obj['synthdet_instance'] = name
        obj['synthdet_class'] = cls
        self.collection.objects.link(obj)
        return obj

    def build(self, layout: RoomLayout, rng: np.random.Generator) -> None:
        """Replace the scene by ``layout``: structure parts, then one object per instance."""
        self.clear()
        for part in structure_parts(layout, rng):
            mesh = mesh_from_arrays(f'room:{part.instance}', part.vertices, part.triangles,
                                    part.colors)
            self._add_object(part.instance, part.cls, mesh)
        for placed in layout.objects:
            if is_procedural(placed.spec):  # sized per room: a mesh of its own
                mesh = mesh_from_arrays(f'room:{placed.instance}', *procedural_mesh(placed.spec))
            else:
                mesh = self._asset_mesh(placed.cls, placed.spec.name)
            self._add_object(placed.instance, placed.cls, mesh, placed.base, placed.yaw)
        bpy.context.view_layer.update()

    def save(self, path: str | Path) -> None:
        """Save the current scene as a .blend file (a copy; the open scene stays in memory)."""
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(path).resolve()), copy=True)


def export_triangles(
    collection_name: str = COLLECTION,
    movable_classes: Sequence[str] = ('table', 'chair', 'sofa', 'yumi', '3dprinter')
) -> tuple[TriangleScene, list[str], list[str]]:
    """Read a room collection back as world triangles.

    Returns the :class:`TriangleScene` and, per part, its instance name and class; parts are the
    collection's objects sorted by name so the order does not depend on creation order.
    """
    collection = bpy.data.collections[collection_name]
    objects = sorted(collection.objects, key=lambda o: o['synthdet_instance'])
    vertices, triangles, colors, part = [], [], [], []
    names, classes = [], []
    offset = 0
    for index, obj in enumerate(objects):
        mesh = obj.data
        n_vert, n_poly = len(mesh.vertices), len(mesh.polygons)
        local = np.empty(3 * n_vert, dtype=np.float32)
        mesh.vertices.foreach_get('co', local)
        sizes = np.empty(n_poly, dtype=np.int32)
        mesh.polygons.foreach_get('loop_total', sizes)
        if n_poly and (sizes != 3).any():
            raise ValueError(f'object {obj.name}: only triangle meshes are supported')
        loops = np.empty(3 * n_poly, dtype=np.int32)
        mesh.loops.foreach_get('vertex_index', loops)
        packed = np.empty(n_poly, dtype=np.int32)
        mesh.attributes['synthdet_rgb'].data.foreach_get('value', packed)
        matrix = np.array(obj.matrix_world, dtype=np.float64)
        world = local.reshape(-1, 3).astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
        vertices.append(world)
        triangles.append(loops.reshape(-1, 3) + offset)
        colors.append(np.stack([(packed >> 16) & 255, (packed >> 8) & 255, packed & 255], 1))
        part.append(np.full(n_poly, index, dtype=np.int32))
        names.append(obj['synthdet_instance'])
        classes.append(obj['synthdet_class'])
        offset += n_vert
    movable = np.array([c in movable_classes for c in classes], dtype=bool)
    scene = TriangleScene(
        vertices=np.concatenate(vertices),
        triangles=np.concatenate(triangles).astype(np.int32),
        colors=np.concatenate(colors).astype(np.uint8),
        part=np.concatenate(part),
        movable=movable)
    return scene, names, classes
