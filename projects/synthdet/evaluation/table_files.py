"""Write a table document as ``<name>.json`` and its text as ``<name>.txt``."""
import json
from pathlib import Path


def write_table(json_path: str | Path, document: dict, text: str) -> Path:
    """Write ``document`` to ``json_path`` and ``text`` next to it with the suffix ``.txt``;
    returns the text file's path."""
    json_path = Path(json_path)
    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json.dumps(document, indent=2) + '\n')
    text_path = json_path.with_suffix('.txt')
    text_path.write_text(text.rstrip('\n') + '\n')
    return text_path
