"""The native stack really works: one real call into each heavy dependency."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch


def test_mmdet3d_registry_builds_model_from_config(tmp_path: Path) -> None:
    from mmengine.config import Config
    from mmdet3d.registry import MODELS
    from mmdet3d.utils import register_all_modules

    register_all_modules(init_default_scope=True)
    config_file = tmp_path / 'backbone.py'
    config_file.write_text(textwrap.dedent("""
        _base_ = ['mmdet3d::_base_/default_runtime.py']
        model = dict(type='MinkResNet', in_channels=3, depth=18)
    """))
    cfg = Config.fromfile(str(config_file))
    assert cfg.default_scope == 'mmdet3d'  # inherited from the mmdet3d base config
    assert MODELS.get('MinkResNet') is not None
    model = MODELS.build(cfg.model)
    n_params = sum(p.numel() for p in model.parameters())
    assert n_params > 1_000_000


def test_minkowski_sparse_conv_forward_backward() -> None:
    import MinkowskiEngine as ME

    torch.manual_seed(0)
    conv = ME.MinkowskiConvolution(2, 3, kernel_size=3, stride=1, dimension=3, bias=False).double()
    grid = [[0, x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)]
    coords = torch.tensor(grid, dtype=torch.int32)
    feats = torch.ones(len(grid), 2, dtype=torch.float64, requires_grad=True)
    out = conv(ME.SparseTensor(feats, coordinates=coords))

    # The centre voxel sees all 27 neighbours with unit features: its output is the sum of
    # every kernel tap, whatever order the taps are stored in.
    centre = (out.C[:, 1:] == 0).all(dim=1)
    expected = conv.kernel.detach().sum(dim=(0, 1))
    torch.testing.assert_close(out.F[centre][0], expected)

    out.F.pow(2).sum().backward()
    assert feats.grad.abs().sum() > 0 and conv.kernel.grad.abs().sum() > 0
    # Analytic gradients agree with finite differences.
    kernel = conv.kernel.detach().clone().requires_grad_(True)
    sparse = ME.SparseTensor(feats.detach().clone().requires_grad_(True), coordinates=coords)
    assert torch.autograd.gradcheck(
        lambda f, k: ME.MinkowskiConvolutionFunction.apply(f, k, conv.kernel_generator, conv.convolution_mode,
                                    sparse.coordinate_map_key, None, sparse.coordinate_manager),
        (sparse.F, kernel))


def test_mmcv_cpu_nms() -> None:
    from mmcv.ops import nms

    boxes = torch.tensor([[0, 0, 10, 10], [1, 1, 10, 10], [20, 20, 30, 30]], dtype=torch.float32)
    scores = torch.tensor([0.9, 0.8, 0.7])
    kept, keep = nms(boxes, scores, iou_threshold=0.5)
    assert keep.tolist() == [0, 2]  # box 1 overlaps box 0 with IoU 0.81
    assert kept.shape == (2, 5)


def test_bpy_blend_save_and_reopen(tmp_path: Path) -> None:
    # In a child process: bpy state is global and other tests should not inherit this scene.
    blend = tmp_path / 'cube.blend'
    script = textwrap.dedent(f"""
        import bpy, json, sys
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.0, 2.0, 3.0))
        bpy.context.active_object.name = 'probe'
        bpy.context.active_object['synthdet'] = 'hello'
        bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.wm.open_mainfile(filepath={str(blend)!r})
        obj = bpy.data.objects['probe']
        print(json.dumps(dict(location=list(obj.location), vertices=len(obj.data.vertices),
                              prop=obj['synthdet'])))
    """)
    result = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                            check=True, timeout=120)
    reopened = json.loads(result.stdout.strip().splitlines()[-1])
    assert reopened == {'location': [1.0, 2.0, 3.0], 'vertices': 8, 'prop': 'hello'}


def test_open3d_raycasting_scene_cast() -> None:
    import open3d as o3d

    box = o3d.geometry.TriangleMesh.create_box(2.0, 2.0, 2.0).translate((-1.0, -1.0, -1.0))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(box))
    directions = np.array([[1, 0, 0], [0, -1, 0], [0, 0, 1]], dtype=np.float32)
    rays = np.hstack([np.zeros((3, 3), dtype=np.float32), directions])
    hits = scene.cast_rays(o3d.core.Tensor(rays))
    np.testing.assert_allclose(hits['t_hit'].numpy(), [1.0, 1.0, 1.0], rtol=1e-6)
    np.testing.assert_allclose(np.abs(hits['primitive_normals'].numpy()), np.abs(directions))


def test_freecadcmd_creates_saves_and_reopens_fcstd(tmp_path: Path) -> None:
    document = tmp_path / 'box.FCStd'
    report = tmp_path / 'report.json'
    create = tmp_path / 'create.py'
    create.write_text(textwrap.dedent("""
        import os
        import FreeCAD
        doc = FreeCAD.newDocument('probe')
        box = doc.addObject('Part::Box', 'Probe')
        box.Length, box.Width, box.Height = 1200.0, 800.0, 750.0
        box.addProperty('App::PropertyString', 'SynthdetClass', 'synthdet')
        box.SynthdetClass = 'table'
        doc.recompute()
        doc.saveAs(os.environ['PROBE_DOC'])
    """))
    reopen = tmp_path / 'reopen.py'
    reopen.write_text(textwrap.dedent("""
        import json, os
        import FreeCAD
        doc = FreeCAD.openDocument(os.environ['PROBE_DOC'])
        box = doc.getObject('Probe')
        bound = box.Shape.BoundBox
        with open(os.environ['PROBE_REPORT'], 'w') as f:
            json.dump(dict(size=[bound.XLength, bound.YLength, bound.ZLength],
                           cls=box.SynthdetClass, volume=box.Shape.Volume), f)
    """))
    env = dict(os.environ, PROBE_DOC=str(document), PROBE_REPORT=str(report))
    for script in (create, reopen):
        subprocess.run(['freecadcmd', str(script)], env=env, capture_output=True, timeout=120)
    # freecadcmd exits 0 even when a script raises: judge by the reopened content only.
    content = json.loads(report.read_text())
    assert content['size'] == pytest.approx([1200.0, 800.0, 750.0])
    assert content['cls'] == 'table'
    assert content['volume'] == pytest.approx(1200.0 * 800.0 * 750.0)
