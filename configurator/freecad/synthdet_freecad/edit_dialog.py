"""The macro's dialog on a synthdet document open in the GUI: add a part, mark the document
reviewed, or import more detections (runs in the FreeCAD GUI only; the work is done by
``editing``, which also runs headless).

"Add" places a part of the picked class at the point last picked in the 3D view (a click on the
floor selects it), else where the view's centre ray meets the floor; it stands on the floor.
"""
import FreeCAD as App

from . import appearance, editing, labels, library

TITLE = 'synthdet: correct the document'


def is_synthdet_document(doc) -> bool:
    """Whether ``doc`` holds synthdet parts or a synthdet room."""
    return bool(labels.synthdet_parts(doc)) or labels.room_outline(doc) is not None


def picked_point() -> tuple[float, float] | None:
    """The (x, y) in metres of the point last picked in the 3D view, if any."""
    import FreeCADGui as Gui
    for selection in reversed(Gui.Selection.getSelectionEx()):
        if selection.PickedPoints:
            point = selection.PickedPoints[-1]
            return point.x / 1000.0, point.y / 1000.0
    return None


def add_in_gui(doc, class_name: str):
    """Add a part of ``class_name`` at the picked point or the view centre, colored by its
    class; returns it."""
    import FreeCADGui as Gui
    where = picked_point()
    if where is None:
        where = editing.view_point(Gui.ActiveDocument.ActiveView, editing.floor_height(doc))
    part = editing.add_part(doc, class_name, *where)
    color = tuple(value / 255.0 for value in appearance.class_color(class_name))
    part.ViewObject.ShapeColor = color
    Gui.Selection.clearSelection()
    Gui.Selection.addSelection(part)
    return part


def run(doc, import_more) -> None:
    """Show the dialog for ``doc``; ``import_more()`` runs the import of more detections."""
    import FreeCADGui as Gui
    from PySide import QtGui

    library.restore_proxies(doc)  # parts opened before the macro loaded their proxy class
    dialog = QtGui.QDialog(Gui.getMainWindow())
    dialog.setWindowTitle(TITLE)
    layout = QtGui.QVBoxLayout(dialog)
    row = QtGui.QHBoxLayout()
    classes = QtGui.QComboBox()
    classes.addItems(list(editing.ADDABLE_CLASSES))
    add = QtGui.QPushButton('Add synthdet object')
    add.setToolTip('at the point picked in the 3D view, else at the view centre, on the floor')
    row.addWidget(classes)
    row.addWidget(add)
    layout.addLayout(row)
    reviewed = QtGui.QCheckBox('Reviewed: every object of the scan is labelled correctly')
    reviewed.setChecked(editing.is_reviewed(doc))
    layout.addWidget(reviewed)
    more = QtGui.QPushButton('Import more detections...')
    close = QtGui.QPushButton('Close')
    layout.addWidget(more)
    layout.addWidget(close)

    def add_part() -> None:
        doc.openTransaction('Add synthdet object')
        try:
            add_in_gui(doc, classes.currentText())
        except ValueError as error:
            doc.abortTransaction()
            QtGui.QMessageBox.critical(dialog, TITLE, str(error))
            return
        doc.commitTransaction()

    def import_detections() -> None:
        dialog.accept()
        import_more()

    add.clicked.connect(add_part)
    reviewed.toggled.connect(lambda checked: editing.set_reviewed(doc, checked))
    more.clicked.connect(import_detections)
    close.clicked.connect(dialog.accept)
    dialog.exec_()
    App.Console.PrintMessage(f'synthdet: {doc.Label} reviewed: {editing.is_reviewed(doc)}\n')
