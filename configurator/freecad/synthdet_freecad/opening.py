"""Open a FreeCAD document a user handed over, once ``synthdet.fcstd_guard`` has checked it
(runs inside FreeCAD; ``labels`` and the screenshot script open documents only this way)."""
import FreeCAD as App
# standard library only, importable wherever schema's synthdet.contracts is
from synthdet.fcstd_guard import check_document


def open_document(path: str):
    """The document at ``path``, opened by FreeCAD after ``check_document`` found nothing
    FreeCAD would run code or open other files for; raises ``RefusedDocument`` otherwise."""
    check_document(path)
    return App.openDocument(path)
