"""Write a table document as ``<name>.json`` and its text as ``<name>.txt``."""
import json
from pathlib import Path

from synthdet.outputs import write_text


def write_table(json_path: str | Path, document: dict, text: str) -> Path:
    """Write ``document`` to ``json_path`` and ``text`` next to it with the suffix ``.txt``,
    each through a checked temporary file (``synthdet.outputs``); returns the text file's
    path."""
    json_path = Path(json_path)
    write_text(json_path, json.dumps(document, indent=2) + '\n')
    text_path = json_path.with_suffix('.txt')
    write_text(text_path, text.rstrip('\n') + '\n')
    return text_path
