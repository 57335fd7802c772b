"""The one check of a FreeCAD document (.FCStd) a user hands over, before FreeCAD opens it.

An .FCStd is a zip. FreeCAD parses the archive's first stored entry as ``Document.xml``
(whatever its name: it reads the entries one after another, not through the zip's directory),
then reads the entries the document names, in stored order; the GUI also reads
``GuiDocument.xml``. Restoring a document runs code or opens other files for:

- a type FreeCAD looks up by name (objects, properties, extensions, geometry): it imports the
  module the name starts with (``Evil::Thing`` imports ``Evil``);
- a Python feature object (``App::FeaturePython``) or any ``<Python>`` element (a proxy's
  state): FreeCAD imports the module it names (or unpickles the state);
- a link into another file (``App::Link``, ``App::PropertyXLink``, ``<XLink file="...">``, a
  ``<DocMap>`` of external documents): FreeCAD opens that file;
- an included file (``App::PropertyFileIncluded``), written to disk under its stored name;
- a DOCTYPE (entity declarations) and a camera that is a whole Inventor scene.

``check_document`` reads the archive the way FreeCAD does and raises ``RefusedDocument`` (a
``ValueError``, one line naming the file, the entry, the line and the element) for any of
these. Allowed are the object types synthdet writes (``SYNTHDET_TYPES``), FreeCAD's plain
built-in ones (``BUILTIN_TYPES``), types of FreeCAD's own modules (``FREECAD_MODULES``) and the
two proxies that run nothing: synthdet's part proxy without state and a JSON null. The XML is
parsed as XML (any whitespace, attribute order or namespace prefix), in chunks and up to
``MAX_XML_BYTES``; an archive with more than ``MAX_ENTRIES`` entries, entries not stored one
after another from the start, or more than one entry FreeCAD could take for ``Document.xml`` or
``GuiDocument.xml`` is refused. Standard library only: it runs in synthdet's Python and inside
FreeCAD's.
"""
import os
import re
import struct
import zipfile
import zlib
from typing import BinaryIO, Iterator, NamedTuple
from xml.parsers import expat

MAX_ENTRIES = 20000  # a synthdet room of 2,000 parts stores about 4,000
MAX_CENTRAL_BYTES = 4 << 20  # the zip directory is read whole: bounded before it is read
MAX_XML_BYTES = 256 << 20  # Document.xml decompressed; a synthdet part takes about 10 KB
CHUNK = 1 << 20  # bytes decompressed and parsed at a time
DOCUMENT_XML, GUI_DOCUMENT_XML = 'Document.xml', 'GuiDocument.xml'
XML_ENTRIES = (DOCUMENT_XML, GUI_DOCUMENT_XML)

SYNTHDET_TYPES = frozenset({
    'App::DocumentObjectGroup', 'App::LinkGroup', 'Part::Extrusion', 'Part::Face',
    'Part::Feature', 'Part::FeaturePython', 'Part::Offset2D', 'Sketcher::SketchObject',
    'Spreadsheet::Sheet'
})  # what the builder writes (App::LinkGroup: parts of the former layout)
BUILTIN_TYPES = frozenset({
    'App::Annotation', 'App::Line', 'App::Origin', 'App::Part', 'App::Placement', 'App::Plane',
    'Part::Box', 'Part::Chamfer', 'Part::Circle', 'Part::Common', 'Part::Compound', 'Part::Cone',
    'Part::Cut', 'Part::Cylinder', 'Part::Ellipse', 'Part::Ellipsoid', 'Part::Fillet',
    'Part::Fuse', 'Part::Helix', 'Part::Line', 'Part::Loft', 'Part::Mirroring',
    'Part::MultiCommon', 'Part::MultiFuse', 'Part::Offset', 'Part::Plane', 'Part::Polygon',
    'Part::Prism', 'Part::RegularPolygon', 'Part::Revolution', 'Part::RuledSurface',
    'Part::Section', 'Part::Sphere', 'Part::Spiral', 'Part::Sweep', 'Part::Thickness',
    'Part::Torus', 'Part::Vertex', 'Part::Wedge'
})
FREECAD_MODULES = frozenset({
    'App', 'Base', 'Gui', 'Part', 'PartGui', 'Sketcher', 'SketcherGui', 'Spreadsheet',
    'SpreadsheetGui'
})  # the modules whose property, extension and geometry types a document may name
PYTHON_OBJECT_PROPERTY = 'App::PropertyPythonObject'  # its <Python> element is checked
SAFE_PROXIES = (
    {'value': 'bnVsbA==', 'encoded': 'yes', 'module': 'synthdet_freecad.library',
     'class': 'DetectionModel'},  # synthdet's part proxy, no state (its module is loaded first)
    {'value': 'bnVsbA==', 'encoded': 'yes', 'json': 'yes'},  # a proxy FreeCAD did not restore
)
TYPE_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*::[A-Za-z][A-Za-z0-9_]*')
# a camera as FreeCAD saves it: one Inventor camera node of plain fields, nothing nested
CAMERA = re.compile(r'\s*(#Inventor V2\.1 ascii\s*)?(Orthographic|Perspective)Camera\s*'
                    r'\{[\w\s.+-]*\}\s*')
LOCAL_HEADER = struct.Struct('<IHHHHHIIIHH')
LOCAL_SIGNATURE, CENTRAL_SIGNATURE, END_SIGNATURE = 0x04034b50, b'PK\x01\x02', b'PK\x05\x06'
END_RECORD = struct.Struct('<4s4H2LH')
ZIP64_LIMIT = 0xFFFFFFFF
ENCRYPTED, DATA_DESCRIPTOR = 0x1, 0x8
STORED, DEFLATED = zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED


class RefusedDocument(ValueError):
    """A file FreeCAD would run code, open other files or work without bound for (or no
    FreeCAD document at all); the message is one line naming the file."""


class Entry(NamedTuple):
    """One archive entry where it is stored: its data starts at ``data_offset``."""
    name: str
    data_offset: int
    method: int
    compressed: int
    size: int
    crc: int


def check_document(path: str | os.PathLike) -> None:
    """Raise ``RefusedDocument`` unless FreeCAD can open the document at ``path`` without
    running code or opening other files: the archive read as FreeCAD reads it, its
    ``Document.xml`` (and ``GuiDocument.xml``) parsed as XML and every element checked."""
    path = os.fspath(path)
    if not os.path.lexists(path):
        raise RefusedDocument(f'{path}: document not found')
    if not os.path.isfile(path):
        raise RefusedDocument(f'{path}: not a regular file (a folder, device or FIFO)')
    try:
        with open(path, 'rb') as stream:
            entries = _stored_entries(stream, path)
            for entry in entries:
                if entry.name in XML_ENTRIES:
                    _check_xml(_entry_chunks(stream, entry, path), f'{path}: {entry.name}')
    except (OSError, EOFError, zipfile.BadZipFile, zlib.error, struct.error,
            UnicodeDecodeError) as error:
        reason = ' '.join(str(error).split())[:100] or type(error).__name__
        raise RefusedDocument(f'{path}: not a FreeCAD document (.FCStd): {reason}') from None


def _shown(text: str, limit: int = 60) -> str:
    """``text`` quoted for a one-line message, at most ``limit`` characters."""
    text = repr(text)
    return text if len(text) <= limit else f'{text[:limit - 4]}...{text[0]}'


def _check_directory_size(stream: BinaryIO, path: str) -> None:
    """Refuse an archive whose zip directory is larger than ``MAX_CENTRAL_BYTES`` (read from
    its end record, found as ``zipfile`` finds it) before ``zipfile`` reads the directory."""
    size = stream.seek(0, os.SEEK_END)
    stream.seek(max(0, size - END_RECORD.size - 0xFFFF))
    tail = stream.read()
    start = len(tail) - END_RECORD.size
    if start < 0 or tail[start:start + 4] != END_SIGNATURE:
        start = tail.rfind(END_SIGNATURE)
    if start < 0 or len(tail) - start < END_RECORD.size:
        raise zipfile.BadZipFile('no zip end record')
    fields = END_RECORD.unpack_from(tail, start)
    if fields[5] > MAX_CENTRAL_BYTES or fields[4] > MAX_ENTRIES:
        raise RefusedDocument(f'{path}: {fields[4]:,} entries in a zip directory of '
                              f'{fields[5]:,} bytes: more than {MAX_ENTRIES:,} entries or '
                              f'{MAX_CENTRAL_BYTES:,} bytes are refused')


def _stored_entries(stream: BinaryIO, path: str) -> list[Entry]:
    """The archive's entries in stored order, checked against its directory: stored one after
    another from the start, each local header naming and sizing its entry as the directory
    does, and exactly one ``Document.xml`` (the first entry) and at most one
    ``GuiDocument.xml``, with no other entry FreeCAD could take for either."""
    _check_directory_size(stream, path)
    with zipfile.ZipFile(stream) as archive:
        listed = sorted(archive.infolist(), key=lambda info: info.header_offset)
    if len(listed) > MAX_ENTRIES:
        raise RefusedDocument(f'{path}: {len(listed):,} entries: more than {MAX_ENTRIES:,} '
                              'are refused')
    entries, offset = [], 0
    for info in listed:
        if info.header_offset != offset:
            raise RefusedDocument(f'{path}: entry {_shown(info.filename)} is not stored where '
                                  'FreeCAD reads it (at the start of the file or right after '
                                  'the entry before it)')
        entry = _local_entry(stream, info, path)
        entries.append(entry)
        offset = entry.data_offset + entry.compressed
    stream.seek(offset)
    if stream.read(4) not in (CENTRAL_SIGNATURE, END_SIGNATURE):
        raise RefusedDocument(f'{path}: data the zip directory does not list follows its last '
                              'entry: FreeCAD would read it as more entries')
    _check_xml_entry_names(entries, path)
    return entries


def _local_entry(stream: BinaryIO, info: zipfile.ZipInfo, path: str) -> Entry:
    """The entry at ``info``'s local header, refused unless that header agrees with the zip
    directory (FreeCAD reads only the local headers)."""
    stream.seek(info.header_offset)
    header = stream.read(LOCAL_HEADER.size)
    if len(header) < LOCAL_HEADER.size:
        raise zipfile.BadZipFile(f'entry {info.filename!r} is cut short')
    (signature, _, flags, method, _, _, crc, compressed, size, name_length,
     extra_length) = LOCAL_HEADER.unpack(header)
    encoding = 'utf-8' if flags & 0x800 else 'cp437'
    name = stream.read(name_length).decode(encoding, 'replace')
    problem = None
    if signature != LOCAL_SIGNATURE:
        problem = 'has no local header where the zip directory says'
    elif flags & (ENCRYPTED | DATA_DESCRIPTOR):
        problem = 'is encrypted or sized after its data (FreeCAD reads neither)'
    elif method not in (STORED, DEFLATED):
        problem = f'uses compression method {method} (FreeCAD reads stored and deflated only)'
    elif ZIP64_LIMIT in (compressed, size):
        problem = 'is larger than 4 GiB'
    elif (name, method, crc, compressed, size) != (info.orig_filename, info.compress_type,
                                                   info.CRC, info.compress_size,
                                                   info.file_size):
        problem = 'has a local header that disagrees with the zip directory'
    if problem is not None:
        raise RefusedDocument(f'{path}: entry {_shown(info.orig_filename)} {problem}')
    data_offset = info.header_offset + LOCAL_HEADER.size + name_length + extra_length
    return Entry(name, data_offset, method, compressed, size, crc)


def _xml_entry_kind(name: str) -> str | None:
    """``Document.xml`` or ``GuiDocument.xml`` if FreeCAD could take an entry of this name for
    it (any case, any folder), else None."""
    base = re.split(r'[/\\]', name.split('\0')[0])[-1].strip().lower()
    return next((kind for kind in XML_ENTRIES if base == kind.lower()), None)


def _check_xml_entry_names(entries: list[Entry], path: str) -> None:
    """Exactly one ``Document.xml``, stored first (what FreeCAD parses), at most one
    ``GuiDocument.xml``, both named exactly so at the top of the archive."""
    if not entries or entries[0].name != DOCUMENT_XML:
        first = _shown(entries[0].name) if entries else 'nothing'
        raise RefusedDocument(f'{path}: not a FreeCAD document (.FCStd): its first entry is '
                              f'{first}, FreeCAD reads the first entry as Document.xml')
    for kind in XML_ENTRIES:
        names = [entry.name for entry in entries if _xml_entry_kind(entry.name) == kind]
        if len(names) > 1 or names and names[0] != kind:
            listed = ', '.join(_shown(name, 40) for name in names[:3])
            raise RefusedDocument(f'{path}: {len(names)} {"entries" if names[1:] else "entry"} '
                                  f'named like {kind} ({listed}): FreeCAD may read another one '
                                  'than the one checked')


def _compressed_chunks(stream: BinaryIO, entry: Entry) -> Iterator[bytes]:
    """The entry's stored bytes, a chunk at a time."""
    stream.seek(entry.data_offset)
    left = entry.compressed
    while left:
        data = stream.read(min(CHUNK, left))
        if not data:
            raise zipfile.BadZipFile(f'{entry.name} is cut short')
        left -= len(data)
        yield data


def _entry_chunks(stream: BinaryIO, entry: Entry, path: str) -> Iterator[bytes]:
    """The entry's data, decompressed a chunk at a time; refused beyond ``MAX_XML_BYTES``.
    Raises ``zipfile.BadZipFile`` unless the data is whole: a deflate stream ending exactly
    at the entry's end, with the size and CRC the entry records."""
    too_large = RefusedDocument(f'{path}: {entry.name} decompresses to more than '
                                f'{MAX_XML_BYTES:,} bytes: refused')
    if entry.size > MAX_XML_BYTES:
        raise too_large
    inflater = zlib.decompressobj(-zlib.MAX_WBITS) if entry.method == DEFLATED else None
    produced = crc = 0
    for data in _compressed_chunks(stream, entry):
        while data:
            if inflater is None:
                chunk, data = data, b''
            else:
                chunk = inflater.decompress(data, CHUNK)
                data = inflater.unconsumed_tail
            produced += len(chunk)
            if produced > MAX_XML_BYTES:
                raise too_large
            crc = zlib.crc32(chunk, crc)
            yield chunk
    if inflater is not None:
        chunk = inflater.flush()  # output zlib still holds: at most a few hundred bytes
        produced, crc = produced + len(chunk), zlib.crc32(chunk, crc)
        yield chunk
        if not inflater.eof or inflater.unused_data:
            raise zipfile.BadZipFile(f'{entry.name}: its deflate data does not end with it')
    if (produced, crc) != (entry.size, entry.crc):
        raise zipfile.BadZipFile(f'{entry.name}: its size or CRC is not the one recorded')


def _check_xml(chunks: Iterator[bytes], where: str) -> None:
    """Parse the XML of ``chunks`` and refuse its first element FreeCAD would run code or
    open other files for; ``where`` (file and entry) starts the message."""
    parser = expat.ParserCreate()

    def refuse(reason: str) -> None:
        raise RefusedDocument(f'{where} line {parser.CurrentLineNumber}: refused {reason}')

    def start_element(tag: str, attributes: dict) -> None:
        reason = element_refusal(tag, attributes)
        if reason is not None:
            refuse(reason)

    def declaration(*_) -> None:
        refuse('a DOCTYPE or entity declaration: a FreeCAD document declares none')

    parser.StartElementHandler = start_element
    parser.StartDoctypeDeclHandler = declaration
    parser.EntityDeclHandler = declaration
    parser.ExternalEntityRefHandler = declaration
    try:
        for chunk in chunks:
            parser.Parse(chunk, False)
        parser.Parse(b'', True)
    except expat.ExpatError as error:
        raise RefusedDocument(f'{where} line {error.lineno}: not well-formed XML '
                              f'({expat.ErrorString(error.code)})') from None


def _local(name: str) -> str:
    """An XML name without its namespace prefix, lower case (how this check compares names:
    FreeCAD's reader may or may not strip the prefix)."""
    return name.rpartition(':')[2].lower()


def element_refusal(tag: str, attributes: dict) -> str | None:
    """Why FreeCAD must not restore the element ``tag`` with ``attributes`` (a reason for the
    message), or None if it is safe."""
    element = _local(tag)
    if element == 'python':
        if attributes in SAFE_PROXIES:
            return None
        module = next((value for name, value in attributes.items() if _local(name) == 'module'),
                      None)
        named = '' if module is None else f' (<Python module={_shown(module)}>)'
        return f'a Python object{named}: FreeCAD would run Python to restore it'

    if element == 'docmap':
        return 'a reference to another document: FreeCAD would open it'
    for name, value in attributes.items():
        attribute = _local(name)
        if element == 'xlink' and attribute == 'file' and value.strip():
            return f'a link to another file ({_shown(value)}): FreeCAD would open it'
        if element == 'camera' and attribute == 'settings' and not CAMERA.fullmatch(value):
            return 'a camera that is not one Inventor camera node: FreeCAD would read a scene'
        if attribute in ('type', 'viewtype'):
            reason = type_refusal(value, is_object=element == 'object' and attribute == 'type')
            if reason is not None:
                return reason
    return None


def type_refusal(type_name: str, is_object: bool) -> str | None:
    """Why a document must not name the type ``type_name`` (``is_object``: as a document
    object's type), or None if FreeCAD creates it without importing anything foreign."""
    if type_name.isdigit():  # a number (a constraint's kind), no type
        return None
    if not TYPE_NAME.fullmatch(type_name):
        return (f'a type name FreeCAD would look up as a module ({_shown(type_name)}): types '
                'are Module::Name')
    folded = type_name.lower()
    python_types = SYNTHDET_TYPES if is_object else {PYTHON_OBJECT_PROPERTY}
    if 'python' in folded and type_name not in python_types:
        return f'a Python object ({type_name}): FreeCAD would run its code'
    if 'xlink' in folded or is_object and 'link' in folded and type_name not in SYNTHDET_TYPES:
        return f'a link ({type_name}): FreeCAD can open other files for it'
    if 'fileincluded' in folded:
        return (f'an included file ({type_name}): FreeCAD would write it to disk under its '
                'stored name')
    if is_object and type_name not in SYNTHDET_TYPES | BUILTIN_TYPES:
        return (f'an object type synthdet opens no document with ({type_name}): synthdet\'s '
                'own and FreeCAD\'s plain built-in types only')
    module = type_name.split('::')[0]
    if module not in FREECAD_MODULES:
        return f'a type of module {module!r} ({type_name}): FreeCAD would import that module'
    return None
