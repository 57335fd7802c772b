"""Known defects of the real S3DIS files, repaired in memory while converting.

S3DIS v1.2 (aligned) has a stray byte inside line 180389 of
``Area_5/hallway_6/Annotations/ceiling_1.txt``, where a space should separate two numbers.
mmdet3d's converter (``data/s3dis/collect_indoor3d_data.py``) rewrites that file with the
character at offset 5,545,347 replaced by a blank. :func:`repaired_point_text` makes the same
repair on the bytes it reads (every byte of that line that cannot be part of an ``x y z r g b``
line becomes a space), so the point is kept and the downloaded file stays untouched.
"""
from pathlib import Path

# (last four path parts, byte offset of the stray byte) of every known defect
KNOWN_STRAY_BYTES = {('Area_5', 'hallway_6', 'Annotations', 'ceiling_1.txt'): 5545347}
POINT_TEXT_BYTES = frozenset(b'0123456789+-.eE \t\r\n')


def repaired_point_text(path: str | Path) -> bytes | None:
    """The content of ``path`` with its known stray byte(s) replaced by spaces, or ``None`` when
    ``path`` has no known defect or the defect is not (or no longer) there."""
    path = Path(path)
    offset = KNOWN_STRAY_BYTES.get(path.parts[-4:])
    if offset is None:
        return None
    data = bytearray(path.read_bytes())
    if offset >= len(data):
        return None
    start = data.rfind(b'\n', 0, offset) + 1
    end = data.find(b'\n', offset)
    end = len(data) if end < 0 else end
    stray = [i for i in range(start, end) if data[i] not in POINT_TEXT_BYTES]
    if not stray:
        return None
    for i in stray:
        data[i] = ord(' ')
    return bytes(data)
