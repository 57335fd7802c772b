"""The one check of a FreeCAD document a user hands over (``synthdet.fcstd_guard``), used by
``configurator labels``, ``configurator screenshot`` and the FreeCAD side that opens documents.

Documents synthdet and plain FreeCAD write pass and still open; every way past the former check
(a tab or newline inside an element, another attribute order, a second ``Document.xml``) and
every object FreeCAD would run code or open other files for is refused with one line naming
the file and the element, before FreeCAD starts; the work is bounded. The documents are real
(``configurator freecad`` and freecadcmd write them); the hostile ones are edited copies.
"""
import json
import os
import struct
import subprocess
import textwrap
import warnings
import zipfile
from pathlib import Path
from typing import Callable

import pytest

from configurator.__main__ import main as configurator_main
from configurator.freecad_cli import MACRO, build_document
from synthdet import fcstd_guard
from synthdet.fcstd_guard import RefusedDocument, check_document
from tests.freecad_gui import WRITE_REPORT, run_gui_driver
from tests.test_configurator.test_labels import run_freecad_script

SAFE_PROXY = (b'<Python value="bnVsbA==" encoded="yes" module="synthdet_freecad.library" '
              b'class="DetectionModel"/>')
DETECTIONS = [('table', (1.5, 1.5), (1.2, 0.8, 0.75)), ('chair', (3.5, 1.5), (0.5, 0.5, 0.9)),
              ('sofa', (2.5, 3.8), (1.8, 0.8, 0.8))]

FREECAD_SCRIPT = textwrap.dedent('''\
    # Runs in freecadcmd: documents plain FreeCAD writes, and ones with Python objects or links.
    import json, os
    import FreeCAD as App
    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    folder = params['folder']

    def saved(name, build):
        doc = App.newDocument(name)
        doc.saveAs(os.path.join(folder, name + '.FCStd'))  # links need a saved document
        build(doc)
        doc.recompute()
        doc.save()
        return doc

    class Thing:  # a Python feature: FreeCAD restores it by importing this module
        pass

    def plain(doc):
        doc.addObject('Part::Box', 'Box')
        part = doc.addObject('App::Part', 'Assembly')
        part.addObject(doc.addObject('Part::Cylinder', 'Cylinder'))

    def former(doc):  # a part as synthdet built it before parts had their own dimensions
        part = doc.addObject('App::LinkGroup', 'Table001')
        part.addProperty('App::PropertyString', 'DetectedClass', 'Synthdet', 'class')
        sheet = doc.addObject('Spreadsheet::Sheet', 'Table001_Parameters')
        sheet.set('B1', '=1600 mm')
        sheet.setAlias('B1', 'length')
        part.ElementList = [sheet]

    other = saved('other', lambda doc: doc.addObject('Part::Box', 'Box'))
    box = other.getObject('Box')

    def python(doc):
        doc.addObject('App::FeaturePython', 'Extra').Proxy = Thing()

    def app_link(doc):
        doc.addObject('App::Link', 'Linked').LinkedObject = box

    def xlink_property(doc):
        feature = doc.addObject('Part::Feature', 'Feature')
        feature.addProperty('App::PropertyXLink', 'Outside')
        feature.Outside = box

    def expression_link(doc):
        doc.addObject('Part::Box', 'Tall').setExpression('Height', 'other#Box.Length * 2')

    for name, build in (('plain', plain), ('former', former), ('python', python),
                        ('app_link', app_link), ('xlink_property', xlink_property),
                        ('expression_link', expression_link)):
        saved(name, build)
    App.openDocument(params['room']).saveAs(os.path.join(folder, 'resaved.FCStd'))
    json.dump({}, open(params['report'], 'w'))
''')


@pytest.fixture(scope='module')
def documents(tmp_path_factory) -> dict:
    """A room built by ``configurator freecad`` (real freecadcmd) with a scan holding points in
    each part, and the documents ``FREECAD_SCRIPT`` writes."""
    root = tmp_path_factory.mktemp('fcstd_guard')
    detections, lines = [], []
    for class_name, (x, y), size in DETECTIONS:
        center = [x, y, size[2] / 2.0]
        detections.append({'class': class_name, 'score': 0.9, 'center': center,
                           'size': list(size), 'yaw': 0.0})
        lines += [f'{x + dx:.3f} {y + dy:.3f} {center[2]:.3f} 90 90 90'
                  for dx in (-0.1, 0.0, 0.1) for dy in (-0.1, 0.0, 0.1)]
    lines += [f'{x:.1f} {y:.1f} 0.0 50 50 50' for x in (0.5, 4.5) for y in (0.5, 4.5)]
    scan = root / 'room.txt'
    scan.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    predictions = root / 'room.pred.json'
    predictions.write_text(json.dumps({
        'format': 'synthdet.predictions/1', 'scan': 'room.txt', 'model': 'test',
        'classes': ['table', 'chair', 'sofa'], 'detections': detections}), encoding='utf-8')
    corners = root / 'room.corners.json'
    corners.write_text(json.dumps({
        'format': 'synthdet.corners/1', 'scan': 'room.txt',
        'corners': [[0, 0], [0, 5], [5, 5], [5, 0]], 'floor_z': 0.0, 'ceiling_z': 2.5,
        'quality': {}}), encoding='utf-8')
    room = root / 'room.FCStd'
    build_document(scan, predictions, room, corners)
    run_freecad_script(root, FREECAD_SCRIPT, {'folder': str(root), 'room': str(room)})
    return {'root': root, 'scan': scan, 'room': room}


def members(path: Path) -> list[tuple[str, bytes]]:
    """The entries of the zip at ``path``, in stored order: (name, data)."""
    with zipfile.ZipFile(path) as archive:
        return [(info.filename, archive.read(info)) for info in archive.infolist()]


def write_zip(path: Path, entries: list[tuple[str, bytes]]) -> Path:
    """A zip at ``path`` holding ``entries`` in this order (names may repeat)."""
    with warnings.catch_warnings(), zipfile.ZipFile(path, 'w', zipfile.ZIP_DEFLATED) as archive:
        warnings.simplefilter('ignore')  # zipfile warns of a repeated name
        for name, data in entries:
            archive.writestr(name, data)
    return path


def directory_offset(data: bytes) -> tuple[int, int]:
    """Where the zip ``data``'s directory starts, and where its end record starts."""
    end = data.rindex(b'PK\x05\x06')
    return struct.unpack_from('<L', data, end + 16)[0], end


def edited(source: Path, target: Path, edit) -> Path:
    """A copy of ``source`` whose Document.xml is ``edit(Document.xml bytes)``."""
    return write_zip(target, [(name, edit(data) if name == 'Document.xml' else data)
                              for name, data in members(source)])


def refusal(path: Path, check: Callable[[Path], None] = check_document,
            refused: type[ValueError] = RefusedDocument) -> str:
    """The one-line message, naming ``path`` first, that ``check`` refuses ``path`` with."""
    with pytest.raises(refused) as error:
        check(path)
    message = str(error.value)
    assert message.startswith(f'{path}:') and '\n' not in message, message
    return message


# ------------------------------------------------------------------ documents that must open


def test_documents_synthdet_and_plain_freecad_write_pass(documents, monkeypatch):
    root = documents['root']
    for name in ('room', 'plain', 'former', 'resaved', 'other'):
        check_document(root / f'{name}.FCStd')
    assert SAFE_PROXY in dict(members(documents['room']))['Document.xml']
    assert b'json="yes"' in dict(members(root / 'resaved.FCStd'))['Document.xml']
    # read and parsed a few bytes at a time: elements cut by a chunk boundary are still seen
    monkeypatch.setattr(fcstd_guard, 'CHUNK', 7)
    check_document(documents['room'])
    python = edited(documents['room'], root / 'chunked.FCStd',
                    lambda xml: xml.replace(SAFE_PROXY, OS_PROXY, 1))
    assert OS_REFUSED in refusal(python)


def test_a_safe_proxy_passes_in_any_attribute_order(documents, tmp_path):
    reordered = (b'<Python class="DetectionModel" encoded="yes"\n\tmodule="synthdet_freecad.'
                 b'library" value="bnVsbA=="/>')
    check_document(edited(documents['room'], tmp_path / 'reordered.FCStd',
                          lambda xml: xml.replace(SAFE_PROXY, reordered)))


SAVE_IN_GUI = textwrap.dedent('''\
    # Runs in the FreeCAD GUI: open the document with synthdet's parts loaded (as after the
    # macro ran), save it as a user does: FreeCAD writes its own GuiDocument.xml.
    import json, os, sys
    import FreeCAD as App
    import FreeCADGui as Gui
    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    sys.path.insert(0, os.path.dirname(params['macro']))
    from synthdet_freecad import library
    doc = App.openDocument(params['document'])
    Gui.updateGui()
    doc.saveAs(params['out'])
    seen = {'proxies': sum(1 for obj in doc.Objects if getattr(obj, 'Proxy', None) is not None)}
''') + WRITE_REPORT


def test_a_document_saved_in_the_freecad_gui_passes(documents, tmp_path):
    saved = tmp_path / 'saved.FCStd'
    seen = run_gui_driver(tmp_path, SAVE_IN_GUI, {'document': str(documents['room']),
                                                   'out': str(saved)})
    assert seen['proxies'] == len(DETECTIONS)
    gui_xml = dict(members(saved))['GuiDocument.xml']
    assert b'<Camera settings=' in gui_xml and b'type="App::PropertyPythonObject"' in gui_xml
    check_document(saved)


def test_labels_reads_a_document_synthdet_wrote(documents, tmp_path, capsys):
    out = tmp_path / 'labels'
    code = configurator_main(['labels', str(documents['room']), '--scan',
                              str(documents['scan']), '--out', str(out)])
    assert code == 0, capsys.readouterr().err
    labels = json.loads((out / 'room.labels.json').read_text(encoding='utf-8'))
    assert sorted(box['class'] for box in labels['boxes']) == ['chair', 'sofa', 'table']


def test_screenshot_opens_a_document_synthdet_wrote(documents, tmp_path, capsys):
    picture = tmp_path / 'room.png'
    code = configurator_main(['screenshot', str(documents['room']), '--out', str(picture),
                              '--width', '200', '--height', '150'])
    assert code == 0, capsys.readouterr().err
    assert picture.stat().st_size > 0


# ------------------------------------------------- ways past the former check, and the rest

OS_PROXY = SAFE_PROXY.replace(b'synthdet_freecad.library', b'os')
OS_REFUSED = "a Python object (<Python module='os'>): FreeCAD would run Python to restore it"
EDITS = {  # case: (old, new) in Document.xml, what the message names
    'tab inside the element': ((SAFE_PROXY, OS_PROXY.replace(b'<Python ', b'<Python\t')),
                               OS_REFUSED),
    'newline inside the element': ((SAFE_PROXY, OS_PROXY.replace(b'<Python ', b'<Python\n ')),
                                   OS_REFUSED),
    'module named before the value': ((SAFE_PROXY, b'<Python module="os" class="C" '
                                       b'encoded="yes" value="bnVsbA=="/>'), OS_REFUSED),
    'namespace prefix': ((SAFE_PROXY, b'<x:Python xmlns:x="urn:x" value="bnVsbA==" '
                          b'encoded="yes" module="os" class="C"/>'), OS_REFUSED),
    'pickled state': ((SAFE_PROXY, b'<Python value="Y29z" encoded="yes" pickle="yes"/>'),
                      'a Python object: FreeCAD would run Python to restore it'),
    'link file after its name': ((b'</Document>',
                                  b'<XLink name="Box" file="other.FCStd"/></Document>'),
                                 "a link to another file ('other.FCStd')"),
    'link file on a new line': ((b'</Document>', b'<XLink\n\tfile="other.FCStd"/></Document>'),
                                "a link to another file ('other.FCStd')"),
    'object type of another module': ((b'type="Part::Extrusion"', b'type="Evil::Extrusion"'),
                                      'an object type synthdet opens no document with '
                                      '(Evil::Extrusion)'),
    'property type of another module': ((b'type="App::PropertyFloat"',
                                         b'type="Evil::PropertyFloat"'),
                                        "a type of module 'Evil' (Evil::PropertyFloat)"),
    'extension written in Python': ((b'type="App::GroupExtension"',
                                     b'type="App::GroupExtensionPython"'),
                                    'a Python object (App::GroupExtensionPython)'),
    'type with spaces': ((b'type="Part::Face"', b'type="Part::\tFace"'), 'a type name'),
    'included file': ((b'type="App::PropertyString"', b'type="App::PropertyFileIncluded"'),
                      'an included file'),
    'entity declarations': ((b'<Document ', b'<!DOCTYPE Document [<!ENTITY a "aaaa">]>'
                             b'<Document '), 'a DOCTYPE or entity declaration'),
    'cut short': ((b'</Document>', b''), 'not well-formed XML'),
}


@pytest.mark.parametrize('case', list(EDITS))
def test_each_way_past_the_former_check_is_refused(documents, tmp_path, case):
    (old, new), expected = EDITS[case]
    document = edited(documents['room'], tmp_path / 'edited.FCStd',
                      lambda xml: xml.replace(old, new, 1))
    assert dict(members(document))['Document.xml'] != dict(members(documents['room']))[
        'Document.xml']
    message = refusal(document)
    assert message.startswith(f'{document}: Document.xml line ') and expected in message, message


def test_python_objects_and_links_freecad_wrote_are_refused(documents):
    root = documents['root']
    expected = {
        'python': 'refused a Python object (App::FeaturePython): FreeCAD would run its code',
        'app_link': 'refused a link (App::Link): FreeCAD can open other files for it',
        'xlink_property': 'refused a link (App::PropertyXLink)',
        'expression_link': 'refused a reference to another document',
    }
    for name, fragment in expected.items():
        message = refusal(root / f'{name}.FCStd')
        assert fragment in message and ': Document.xml line ' in message, message


def test_every_entry_freecad_could_take_for_document_xml_is_checked(documents, tmp_path):
    entries = members(documents['room'])
    clean = dict(entries)['Document.xml']
    hostile = clean.replace(b'synthdet_freecad.library', b'os', 1)
    rest = [(name, data) for name, data in entries if name != 'Document.xml']
    cases = {  # FreeCAD parses the first stored entry, whatever its name
        'second': [('Document.xml', hostile), *rest, ('Document.xml', clean)],
        'cased': [('Document.xml', clean), ('document.xml', hostile), *rest],
        'folder': [('Document.xml', clean), ('backup/Document.xml', hostile), *rest],
        'gui': [*entries, ('GuiDocument.xml', b'<Document/>')],
    }
    for case, variant in cases.items():
        message = refusal(write_zip(tmp_path / f'{case}.FCStd', variant))
        assert '2 entries named like ' in message and 'FreeCAD may read another one' in message
    renamed = write_zip(tmp_path / 'renamed.FCStd', [('notes.xml', hostile), *rest])
    assert "its first entry is 'notes.xml'" in refusal(renamed)


def test_the_zip_is_read_as_freecad_reads_it(documents, tmp_path):
    data = documents['room'].read_bytes()
    directory, end = directory_offset(data)
    # an entry the zip directory does not list, after the listed ones: FreeCAD reads it
    hidden = write_zip(tmp_path / 'one.zip', [('GuiDocument.xml', b'<Document/>')]).read_bytes()
    hidden = hidden[:directory_offset(hidden)[0]]
    moved = struct.pack('<L', directory + len(hidden))
    smuggled = tmp_path / 'smuggled.FCStd'
    smuggled.write_bytes(data[:directory] + hidden + data[directory:end + 16] + moved +
                         data[end + 20:])
    assert 'data the zip directory does not list follows its last entry' in refusal(smuggled)
    # a local header sizing Document.xml other than the directory does
    resized = tmp_path / 'resized.FCStd'
    resized.write_bytes(data[:22] + struct.pack('<L', 5) + data[26:])
    assert "entry 'Document.xml' has a local header that disagrees" in refusal(resized)
    # data before the first entry
    prefixed = tmp_path / 'prefixed.FCStd'
    prefixed.write_bytes(b'#!/bin/sh\n' + data)
    assert "entry 'Document.xml' is not stored where FreeCAD reads it" in refusal(prefixed)


def test_the_gui_document_is_checked_too(documents, tmp_path):
    entries = [(name, data) for name, data in members(documents['room'])
               if name != 'GuiDocument.xml']
    proxy = (b'<Document SchemaVersion="1"><ViewProviderData Count="1"><ViewProvider name="A">'
             b'<Properties Count="1"><Property name="Proxy" type="App::PropertyPythonObject">'
             b'<Python value="bnVsbA==" encoded="yes" module="evil" class="V"/></Property>'
             b'</Properties></ViewProvider></ViewProviderData></Document>')
    scene = (b'<Document SchemaVersion="1"><Camera settings="OrthographicCamera { }&#10;'
             b'File { name &quot;/etc/passwd&quot; }"/></Document>')
    for name, xml, expected in (('proxy', proxy, "a Python object (<Python module='evil'>)"),
                                ('scene', scene, 'a camera that is not one Inventor camera')):
        document = write_zip(tmp_path / f'{name}.FCStd', [*entries, ('GuiDocument.xml', xml)])
        message = refusal(document)
        assert f'{document}: GuiDocument.xml line 1: refused ' in message and expected in message


def test_the_work_is_bounded(documents, tmp_path, monkeypatch):
    crowded = [('Document.xml', b'<Document/>')] + [(f'{index}.brp', b'')
                                                    for index in range(fcstd_guard.MAX_ENTRIES)]
    message = refusal(write_zip(tmp_path / 'many.FCStd', crowded))
    assert '20,001 entries in a zip directory of ' in message
    assert 'more than 20,000 entries or 4,194,304 bytes are refused' in message
    monkeypatch.setattr(fcstd_guard, 'MAX_XML_BYTES', 1 << 20)
    padded = edited(documents['room'], tmp_path / 'padded.FCStd',
                    lambda xml: xml.replace(b'</Document>', b' ' * (2 << 20) + b'</Document>'))
    assert 'Document.xml decompresses to more than 1,048,576 bytes' in refusal(padded)
    # a zip bomb: its headers claim a small Document.xml, the data decompresses to much more
    data = bytearray(padded.read_bytes())
    central = directory_offset(bytes(data))[0]  # Document.xml's header comes first
    for size_field in (22, central + 24):
        data[size_field:size_field + 4] = struct.pack('<L', 1000)
    bomb = tmp_path / 'bomb.FCStd'
    bomb.write_bytes(bytes(data))
    assert 'Document.xml decompresses to more than 1,048,576 bytes' in refusal(bomb)


# ---------------------------------------------------------- the commands that open documents


def test_labels_and_screenshot_refuse_with_one_line_before_freecad_starts(
        documents, tmp_path, capsys):
    tab = edited(documents['room'], tmp_path / 'tab.FCStd',
                 lambda xml: xml.replace(SAFE_PROXY, OS_PROXY.replace(b'<Python ', b'<Python\t')))
    [(_, clean), *rest] = members(documents['room'])
    python = dict(members(documents['root'] / 'python.FCStd'))['Document.xml']
    second = write_zip(tmp_path / 'second.FCStd',
                       [('Document.xml', python), *rest, ('Document.xml', clean)])
    for document, expected in ((tab, f'refused {OS_REFUSED}'),
                               (second, '2 entries named like Document.xml'),
                               (documents['root'] / 'python.FCStd', 'App::FeaturePython'),
                               (documents['root'] / 'app_link.FCStd', 'App::Link')):
        out, picture = tmp_path / 'out', tmp_path / 'picture.png'
        commands = (['labels', str(document), '--scan', str(documents['scan']), '--out',
                     str(out)], ['screenshot', str(document), '--out', str(picture)])
        for command in commands:
            assert configurator_main(command) == 2, command
            error = capsys.readouterr().err
            assert error.startswith(f'error: {document}: ') and error.count('\n') == 1, error
            assert expected in error, error
        assert not out.exists() and not picture.exists()


def test_the_freecad_side_refuses_by_itself(documents, tmp_path):
    """The macro's reader (``SYNTHDET_READ``, what ``labels`` runs) checks before it opens."""
    result = tmp_path / 'result.json'
    env = dict(os.environ, SYNTHDET_READ=str(documents['root'] / 'python.FCStd'),
               SYNTHDET_RESULT=str(result))
    subprocess.run(['freecadcmd', str(MACRO)], env=env, cwd=tmp_path, capture_output=True,
                   timeout=300)
    report = json.loads(result.read_text(encoding='utf-8'))
    assert report['status'] == 'error' and report['kind'] == 'input', report
    assert 'refused a Python object (App::FeaturePython)' in report['error']
