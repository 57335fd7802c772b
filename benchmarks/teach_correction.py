"""Runs in freecadcmd (benchmarks/bench_teach.py): applies a correction plan to a synthdet
document like a user in the property editor, saves it and writes a result file.

The plan (``SYNTHDET_CORRECTION``, JSON) names the document, the output, the parts to keep with
their target boxes (``edit``) and the boxes to add (``add``); every other part is deleted. The
result (``SYNTHDET_RESULT``) counts what was deleted, edited and added.
"""
import json
import math
import os
import sys

plan = json.load(open(os.environ['SYNTHDET_CORRECTION'], encoding='utf-8'))
sys.path.insert(0, plan['freecad_dir'])
sys.path.append(plan['repo'])
import FreeCAD as App
from synthdet_freecad import editing, labels  # editing loads the parts' classes


SIZE_PROPERTIES = ('Length', 'Width', 'Height')


def set_size(doc, part, size: list) -> None:
    """The part's own size properties, or the cells of its parameter sheet (older
    documents), set to ``size`` (metres)."""
    if all(name in part.PropertiesList for name in SIZE_PROPERTIES):
        for name, metres in zip(SIZE_PROPERTIES, size):
            setattr(part, name, 1000.0 * metres)
        return
    sheet = labels.parameter_sheet(doc, part)
    for alias, metres in zip(labels.SIZE_ALIASES, size):
        sheet.set(sheet.getCellFromAlias(alias), '=%.3f mm' % (1000.0 * metres))


def place(part, box: dict) -> None:
    """The part's base centre and angle about z set to the box's."""
    part.setExpression('.Placement.Base.z', None)
    bottom = box['center'][2] - box['size'][2] / 2.0
    part.Placement = App.Placement(
        App.Vector(1000.0 * box['center'][0], 1000.0 * box['center'][1], 1000.0 * bottom),
        App.Rotation(App.Vector(0, 0, 1), math.degrees(box['yaw'])))


def delete(doc, parts: list) -> None:
    """Remove the parts with their children and parameter sheets."""
    names = []  # all names first: a sheet may also be a child, a child go with its part
    for part in parts:
        sheet = doc.getObject(part.Name + '_Parameters')
        names += [obj.Name for obj in labels.part_children(part) + [sheet]
                  if obj is not None] + [part.Name]
    for name in dict.fromkeys(names):
        if doc.getObject(name) is not None:
            doc.removeObject(name)


def correct() -> dict:
    """Apply the plan, save the document; what was done."""
    doc = App.openDocument(plan['document'])
    parts = labels.synthdet_parts(doc)
    edits = {item['name']: item['box'] for item in plan['edit']}
    for part in parts:  # free the heights bound to other parts before any is deleted
        if part.Name in edits:
            part.setExpression('.Placement.Base.z', None)
    unmatched = [part for part in parts if part.Name not in edits]
    delete(doc, unmatched)
    for name, box in edits.items():
        part = doc.getObject(name)
        set_size(doc, part, box['size'])
        place(part, box)
    floor_z = editing.floor_height(doc)
    for box in plan['add']:
        part = editing.add_part(doc, box['class'], box['center'][0], box['center'][1],
                                box['yaw'], tuple(box['size']))
        if abs(box['center'][2] - box['size'][2] / 2.0 - floor_z) > 0.001:
            place(part, box)  # not on the floor: lifted like a user setting its z
    editing.set_reviewed(doc)
    doc.recompute()
    doc.saveAs(plan['out'])
    return {'status': 'ok', 'deleted': len(unmatched), 'edited': len(edits),
            'added': len(plan['add']),
            'invalid': [obj.Name for obj in doc.Objects if not obj.isValid()]}


try:
    result = correct()
except Exception as error:  # the process boundary: every failure goes to the result file
    result = {'status': 'error', 'error': '%s: %s' % (type(error).__name__, error)}
temporary = os.environ['SYNTHDET_RESULT'] + '.tmp'
with open(temporary, 'w', encoding='utf-8') as stream:
    json.dump(result, stream)
os.replace(temporary, os.environ['SYNTHDET_RESULT'])
