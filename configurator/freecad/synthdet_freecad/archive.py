"""Saving a document in time linear in its parts (runs inside FreeCAD).

FreeCAD 0.20 stores every shape as a file of the ``.FCStd`` archive named ``PartShape<N>.brp``
and finds each free N by going through the names of all files stored before it, so its save
takes time in the square of the shapes. ``save_copy`` lets FreeCAD save the document without
the detection parts' shapes (their ``Shape`` property marked ``Transient`` for that save),
then writes the archive once more with each part's shape as a file of its own name
(``<part name>.Shape.brp``), referenced from ``Document.xml`` the way FreeCAD references its
own. The result is a plain FreeCAD document: any FreeCAD opens it with every shape, and saving
it from FreeCAD rewrites it the usual way.
"""
import os
import re
import zipfile

from . import library

DOCUMENT_XML = 'Document.xml'
COMPRESSION_LEVEL = 3  # FreeCAD's own default for documents
SHAPE_SUFFIX = '.Shape.brp'
# an object's properties element and the transient property elements that open it
OBJECT_PROPERTIES = re.compile(
    rb'(<Object name="([^"]+)"[^>]*>\s*<Properties Count=")(\d+)(" TransientCount=")(\d+)(">)'
    rb'((?:\s*<_Property [^>]*/>)*)')
TRANSIENT_SHAPE = re.compile(rb'\s*<_Property name="Shape" type="Part::PropertyPartShape" '
                             rb'status="\d+"/>')
FILE_REFERENCE = re.compile(rb' file="([^"]+)"')


def detection_parts(doc) -> list:
    """The document's detection parts (whose shapes synthdet stores itself)."""
    return [
        obj for obj in doc.Objects
        if obj.TypeId == library.PART_TYPE and 'DetectedClass' in obj.PropertiesList
    ]


def incomplete(path: str) -> OSError:
    """The error of a document that could not be written whole."""
    return OSError(f'FreeCAD could not write a complete document to {path!r} (disk full?); '
                   'the previous document is kept')


def save_copy(doc, path: str, check=None) -> None:
    """Save ``doc`` to ``path`` with every part's shape stored under the part's name.

    ``check(path)``, if given, runs on the archive FreeCAD wrote before it is written again
    (FreeCAD reports some write errors only on its console). The second archive is written
    beside ``path`` and renamed over it; a failure to write it is ``incomplete(path)``.
    """
    parts = detection_parts(doc)
    for part in parts:
        part.setPropertyStatus('Shape', 'Transient')
    try:
        doc.saveCopy(path)
    finally:
        for part in parts:
            part.setPropertyStatus('Shape', '-Transient')
    if check is not None:
        check(path)
    shapes = {part.Name: part.Shape for part in parts}
    temporary = f'{path}.shapes'  # beside ``path``, named after it: cleaned up with it
    try:
        _rewrite(path, temporary, shapes)
    except (OSError, zipfile.BadZipFile):
        raise incomplete(path) from None
    finally:
        if os.path.isfile(temporary):
            os.remove(temporary)


def _rewrite(path: str, temporary: str, shapes: dict) -> None:
    """Write ``path``'s archive again as ``temporary`` with the ``shapes`` (part name ->
    shape) stored and referenced, and rename it over ``path``."""
    with zipfile.ZipFile(path) as source:
        xml = reference_shapes(source.read(DOCUMENT_XML), set(shapes))
        with zipfile.ZipFile(temporary, 'w', zipfile.ZIP_DEFLATED,
                             compresslevel=COMPRESSION_LEVEL) as target:
            # Document.xml first, then the files in the order Document.xml names them:
            # FreeCAD reads the archive front to back, each file when it is asked for
            target.writestr(DOCUMENT_XML, xml)
            written = {DOCUMENT_XML}
            stored = set(source.namelist())
            for match in FILE_REFERENCE.finditer(xml):
                name = match.group(1).decode('utf-8')
                if name in written:
                    continue
                if name.endswith(SHAPE_SUFFIX) and name[:-len(SHAPE_SUFFIX)] in shapes:
                    target.writestr(name, shapes[name[:-len(SHAPE_SUFFIX)]]
                                    .exportBrepToString())
                elif name in stored:
                    target.writestr(name, source.read(name))
                else:
                    continue
                written.add(name)
            for name in source.namelist():  # files no element names (none FreeCAD asks)
                if name not in written:
                    target.writestr(name, source.read(name))
    os.replace(temporary, path)


def reference_shapes(xml: bytes, names: set[str]) -> bytes:
    """``Document.xml`` with the transient ``Shape`` of every object in ``names`` turned into
    a stored one, kept in the file ``<name>.Shape.brp``."""

    def stored(match) -> bytes:
        name = match.group(2).decode('utf-8')
        transients = match.group(7)
        if name not in names or TRANSIENT_SHAPE.search(transients) is None:
            return match.group(0)
        count, transient_count = int(match.group(3)) + 1, int(match.group(5)) - 1
        element = (f'\n<Property name="Shape" type="Part::PropertyPartShape">\n'
                   f'<Part file="{name}{SHAPE_SUFFIX}"/>\n</Property>').encode('utf-8')
        return (match.group(1) + str(count).encode() + match.group(4) +
                str(transient_count).encode() + match.group(6) +
                TRANSIENT_SHAPE.sub(b'', transients, count=1) + element)

    return OBJECT_PROPERTIES.sub(stored, xml)
