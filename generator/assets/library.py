"""The asset library: procedural instances saved as one `<class>.blend` per class, and the loader
that reads procedural or user-made `.blend` files into triangle arrays.

A `.blend` library file `<class>.blend` holds a collection named `<class>`; each mesh object in it
is one instance (see docs/assets.md).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Mapping, Sequence

import bpy
import numpy as np
from tqdm import tqdm

from generator.assets import chair, printer3d, sofa, table, yumi
from generator.assets.builder import material_color
from synthdet.outputs import replaced_paths

ASSET_CLASSES = ('table', 'chair', 'sofa', 'yumi', '3dprinter')
GENERATORS: dict[str, ModuleType] = {
    'table': table,
    'chair': chair,
    'sofa': sofa,
    'yumi': yumi,
    '3dprinter': printer3d
}
ASSET_PROP = 'synthdet_asset'
PARAMS_PROP = 'synthdet_params'
DEFAULT_COLOR = (128, 128, 128)
UP_NORMAL_Z = 0.99


@dataclasses.dataclass(frozen=True)
class AssetInstance:
    """One model of a class, in its local frame: x/y centred on its bounding box, z = 0 at its
    lowest point, front towards -y. Arrays are read-only and shared, so `mesh_arrays` is free."""
    cls: str
    name: str
    asset: str
    params: dict
    size: tuple[float, float, float]
    top_z: float | None
    top_size: tuple[float, float] | None
    vertices: np.ndarray = dataclasses.field(repr=False, compare=False)
    triangles: np.ndarray = dataclasses.field(repr=False, compare=False)
    colors: np.ndarray = dataclasses.field(repr=False, compare=False)

    def mesh_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(vertices (V,3) float64 in the local frame, triangles (T,3) int32, face colors (T,3)
        uint8)."""
        return self.vertices, self.triangles, self.colors


class AssetLibrary:
    """Instances per class, as loaded from `.blend` files."""

    def __init__(self, instances: Mapping[str, Sequence[AssetInstance]]) -> None:
        self._instances = {cls: tuple(items) for cls, items in instances.items()}

    def instances(self, cls: str) -> list[AssetInstance]:
        """The instances of class `cls`."""
        if cls not in self._instances:
            raise KeyError(f'asset library has no class {cls!r}; it has {self.classes()}')
        return list(self._instances[cls])

    def classes(self) -> tuple[str, ...]:
        """The classes present, in ASSET_CLASSES order (then any others)."""
        known = [cls for cls in ASSET_CLASSES if cls in self._instances]
        return tuple(known + sorted(set(self._instances) - set(known)))


def generators_version() -> str:
    """A short hash of the generator sources; the cache key of `default_library`."""
    digest = hashlib.sha256()
    folder = Path(__file__).parent
    for path in sorted(folder.glob('*.py')):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def _check_classes(classes: Sequence[str]) -> None:
    unknown = [cls for cls in classes if cls not in ASSET_CLASSES]
    if unknown:
        raise ValueError(f'unknown asset class(es) {unknown}; known: {ASSET_CLASSES}')


def procedural_params(cls: str, index: int, seed: int) -> tuple[str, dict]:
    """(variant, params) of procedural instance `index` of class `cls` for `seed`."""
    rng = np.random.default_rng([seed, ASSET_CLASSES.index(cls), index])
    return GENERATORS[cls].sample_params(rng, index)


def build_library(out_dir: Path,
                  instances_per_class: int = 24,
                  seed: int = 0,
                  classes: Sequence[str] = ASSET_CLASSES) -> list[Path]:
    """Build the procedural instances in bpy and save one `<class>.blend` per class in out_dir."""
    _check_classes(classes)
    if instances_per_class < 1:
        raise ValueError(f'instances_per_class must be >= 1, got {instances_per_class}')
    if seed < 0:
        raise ValueError(f'seed must be >= 0, got {seed}')
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    with tqdm(total=instances_per_class * len(classes), desc='assets', unit='instance') as bar:
        for cls in classes:
            collection = bpy.data.collections.new(cls)
            x = 0.0
            try:
                if collection.name != cls:
                    raise RuntimeError(f'cannot build {cls}.blend: the open Blender file already '
                                       f'holds a collection named {cls!r}')
                for index in range(instances_per_class):
                    variant, params = procedural_params(cls, index, seed)
                    name = f'{cls}_{variant}_{index:02d}'
                    obj = GENERATORS[cls].build(variant, params).to_object(name, collection)
                    if obj.name != name:
                        raise RuntimeError(f'cannot build {name!r}: the open Blender file already '
                                           f'holds an object of that name')
                    obj[ASSET_PROP] = f'{cls}/{variant}'
                    obj[PARAMS_PROP] = json.dumps(params, sort_keys=True)
                    # side by side, so the file is pleasant to open in Blender
                    lo, hi = _bounds(obj)
                    obj.location = (x - lo[0], -0.5 * (lo[1] + hi[1]), -lo[2])
                    x += hi[0] - lo[0] + 0.3
                    bar.update()
                path = out_dir / f'{cls}.blend'
                with replaced_paths([path]) as (partial, ):
                    bpy.data.libraries.write(str(partial), {collection}, fake_user=True)
                paths.append(path)
            finally:
                _remove_collection(collection)
    return paths


def instance_from_params(cls: str,
                         variant: str,
                         params: dict,
                         name: str | None = None) -> AssetInstance:
    """Build one procedural instance in bpy from explicit parameters (e.g. chosen YuMi joint
    angles) and extract it exactly as `load_library` would, without writing a file."""
    _check_classes([cls])
    name = name or f'{cls}_{variant}'
    collection = bpy.data.collections.new(f'{cls}.scratch')
    try:
        obj = GENERATORS[cls].build(variant, params).to_object(name, collection)
        obj[ASSET_PROP] = f'{cls}/{variant}'
        obj[PARAMS_PROP] = json.dumps(params, sort_keys=True)
        instance = instance_from_object(obj, cls, Path('<memory>'))
        return dataclasses.replace(instance, name=name)
    finally:
        _remove_collection(collection)


def _bounds(obj: bpy.types.Object) -> tuple[np.ndarray, np.ndarray]:
    coords = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get('co', coords)
    coords = coords.reshape(-1, 3)
    return coords.min(0).astype(np.float64), coords.max(0).astype(np.float64)


def _remove_collection(collection: bpy.types.Collection) -> None:
    for obj in list(collection.objects):
        mesh = obj.data
        materials = [m for m in mesh.materials if m is not None]
        bpy.data.objects.remove(obj)
        bpy.data.meshes.remove(mesh)
        for material in materials:
            if material.users == 0:
                bpy.data.materials.remove(material)
    bpy.data.collections.remove(collection)


def load_library(directory: Path) -> AssetLibrary:
    """Load `<class>.blend` files (procedural or user-made) into an AssetLibrary."""
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f'asset library folder {directory} does not exist')
    found = {}
    for cls in ASSET_CLASSES:
        path = directory / f'{cls}.blend'
        if path.is_file():
            found[cls] = load_blend(path, cls)
    if not found:
        raise FileNotFoundError(
            f'{directory}: no asset library file; expected <class>.blend for a class in '
            f'{ASSET_CLASSES}')
    return AssetLibrary(found)


def load_blend(path: Path, cls: str) -> list[AssetInstance]:
    """The instances of one `<class>.blend` file: the mesh objects of its collection `cls`,
    sorted by object name."""
    path = Path(path)
    with bpy.data.libraries.load(str(path), link=True) as (source, target):
        if cls not in source.collections:
            raise ValueError(f'{path}: no collection named {cls!r} '
                             f'(collections in the file: {list(source.collections)})')
        target.collections = [cls]
    collection = target.collections[0]
    library = collection.library
    try:
        objects = sorted((o for o in collection.all_objects if o.type == 'MESH'),
                         key=lambda o: o.name)
        if not objects:
            raise ValueError(f'{path}: collection {cls!r} holds no mesh object')
        return [instance_from_object(obj, cls, path) for obj in objects]
    finally:
        bpy.data.libraries.remove(library)


def _object_linear(obj: bpy.types.Object) -> np.ndarray:
    """Rotation/scale (3x3) of the object's world transform, from its own transform and its
    parents' (no depsgraph needed). Translations do not matter: instances are re-centred."""
    matrix = np.array(obj.matrix_basis, dtype=np.float64)
    if obj.parent is not None:
        parent = np.eye(4)
        parent[:3, :3] = _object_linear(obj.parent)
        matrix = parent @ np.array(obj.matrix_parent_inverse, np.float64) @ matrix
    return matrix[:3, :3]


def instance_from_object(obj: bpy.types.Object, cls: str, path: Path) -> AssetInstance:
    """Extract the triangles, colors and metadata of one library object."""
    where = f'{path}: object {obj.name!r}'
    mesh = obj.data
    mesh.calc_loop_triangles()
    count = len(mesh.loop_triangles)
    if count == 0:
        raise ValueError(f'{where} has no faces')
    triangles = np.empty(count * 3, np.int32)
    mesh.loop_triangles.foreach_get('vertices', triangles)
    material_index = np.empty(count, np.int32)
    mesh.loop_triangles.foreach_get('material_index', material_index)
    coords = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get('co', coords)
    vertices = coords.reshape(-1, 3).astype(np.float64) @ _object_linear(obj).T
    used, triangles = np.unique(triangles, return_inverse=True)
    vertices = vertices[used]
    triangles = triangles.reshape(-1, 3).astype(np.int32)
    low, high = vertices.min(0), vertices.max(0)
    vertices = vertices - np.array([(low[0] + high[0]) / 2, (low[1] + high[1]) / 2, low[2]])
    size = tuple(float(s) for s in vertices.max(0) - vertices.min(0))

    palette = [material_color(slot.material, DEFAULT_COLOR) for slot in obj.material_slots]
    palette = np.array(palette or [DEFAULT_COLOR], np.uint8)
    colors = palette[np.clip(material_index, 0, len(palette) - 1)]

    asset = str(obj.get(ASSET_PROP, f'{cls}/{obj.name}'))
    if not asset.startswith(f'{cls}/'):
        raise ValueError(f'{where}: {ASSET_PROP} {asset!r} must start with {cls + "/"!r}')
    try:
        params = json.loads(obj.get(PARAMS_PROP, '{}'))
    except json.JSONDecodeError as error:
        raise ValueError(f'{where}: {PARAMS_PROP} is not valid JSON ({error})') from None
    if not isinstance(params, dict):
        raise ValueError(f'{where}: {PARAMS_PROP} must be a JSON object')

    top_z = top_size = None
    if cls == 'table':
        top_z = size[2]
        top_size = _top_extent(vertices, triangles, top_z)
        if 'top_size' in params:  # a declared usable area (e.g. inside a round top) may shrink it
            top_size = tuple(min(float(a), b) for a, b in zip(params['top_size'], top_size))
    for array in (vertices, triangles, colors):
        array.setflags(write=False)
    return AssetInstance(
        cls=cls,
        name=obj.name,
        asset=asset,
        params=params,
        size=size,
        top_z=top_z,
        top_size=top_size,
        vertices=vertices,
        triangles=triangles,
        colors=colors)


def _top_extent(vertices: np.ndarray, triangles: np.ndarray, top_z: float) -> tuple[float, float]:
    """x/y extent, centred at the origin, of the upward faces at the top height."""
    corners = vertices[triangles]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    up = (lengths > 0) & (normals[:, 2] > UP_NORMAL_Z * np.maximum(lengths, 1e-30))
    up &= np.all(corners[:, :, 2] >= top_z - 1e-4, axis=1)
    points = corners[up].reshape(-1, 3) if up.any() else vertices
    low, high = points[:, :2].min(0), points[:, :2].max(0)
    half = np.minimum(-low, high).clip(min=0.0)
    return float(2 * half[0]), float(2 * half[1])


def default_library(cache_dir: Path, seed: int = 0) -> AssetLibrary:
    """Build (once, cached by seed + a version of the generators) and load the procedural
    library."""
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    target = cache_dir / f'procedural-{generators_version()}-seed{seed}'
    if not all((target / f'{cls}.blend').is_file() for cls in ASSET_CLASSES):
        if target.exists():
            shutil.rmtree(target)
        staging = Path(tempfile.mkdtemp(prefix=f'.{target.name}.', dir=cache_dir))
        try:
            build_library(staging, seed=seed)
            os.replace(staging, target)
        except OSError:
            if not target.is_dir():  # not a lost race with another process: a real error
                raise
        finally:
            if staging.exists():
                shutil.rmtree(staging)
    return load_library(target)
