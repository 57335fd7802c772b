"""Preview pictures of an asset library: one PNG per class with every instance drawn as shaded,
colored triangles in an orthographic 3D view (matplotlib, headless)."""
from __future__ import annotations

import io
import math
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from generator.assets.library import AssetInstance, AssetLibrary  # noqa: E402
from synthdet.outputs import write_bytes  # noqa: E402

LIGHT = np.array([-0.4, -0.7, 0.6]) / np.linalg.norm([-0.4, -0.7, 0.6])


def shaded_colors(instance: AssetInstance) -> np.ndarray:
    """Face colors (T,3) in [0, 1], darkened by a two-sided Lambert term for depth cues."""
    vertices, triangles, colors = instance.mesh_arrays()
    corners = vertices[triangles]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    shade = 0.45 + 0.55 * np.abs(normals @ LIGHT)
    return np.clip(colors / 255.0 * shade[:, None], 0.0, 1.0)


def draw_instance(ax, instance: AssetInstance) -> None:
    """Draw one instance on a 3D axis, viewed from its front-left, with true proportions."""
    vertices, triangles, _ = instance.mesh_arrays()
    ax.add_collection3d(
        Poly3DCollection(
            vertices[triangles], facecolors=shaded_colors(instance), edgecolors='none'))
    half = 0.5 * np.asarray(instance.size)
    ax.set_xlim(-half[0], half[0])
    ax.set_ylim(-half[1], half[1])
    ax.set_zlim(0.0, 2 * half[2])
    ax.set_box_aspect(tuple(max(s, 1e-3) for s in instance.size))
    ax.set_proj_type('ortho')
    ax.view_init(elev=22, azim=-60)
    ax.set_axis_off()
    ax.set_title(f'{instance.name}\n{" x ".join(f"{s:.2f}" for s in instance.size)} m', fontsize=7)


def render_previews(library: AssetLibrary, out_dir: Path, columns: int = 4) -> list[Path]:
    """Write `<class>.png` for every class of the library into out_dir; returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for cls in library.classes():
        instances = library.instances(cls)
        rows = math.ceil(len(instances) / columns)
        fig = plt.figure(figsize=(3.2 * columns, 3.2 * rows), dpi=110)
        for k, instance in enumerate(instances):
            draw_instance(fig.add_subplot(rows, columns, k + 1, projection='3d'), instance)
        fig.suptitle(f'{cls}: {len(instances)} instances', fontsize=11)
        fig.tight_layout()
        path = out_dir / f'{cls}.png'
        picture = io.BytesIO()
        fig.savefig(picture, format='png')
        plt.close(fig)
        write_bytes(path, picture.getvalue())
        paths.append(path)
    return paths
