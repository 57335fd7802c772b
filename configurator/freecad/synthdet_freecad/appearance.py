"""What the document looks like when opened: visibility, a color per class, the first view.

Runs inside FreeCAD. Colors, visibility and the camera belong to FreeCAD's GUI side (view
providers), which ``freecadcmd`` neither creates nor saves: a document it writes has no
``GuiDocument.xml`` and opens with every object hidden. So the build records a ``Look`` (object
name -> color, transparency) and then either applies it to the view providers (macro in the
GUI) or writes it as the ``GuiDocument.xml`` FreeCAD itself would have saved (headless), with
an isometric camera fitted to the room.
"""
import os
import zipfile
from xml.sax.saxutils import escape, quoteattr

import FreeCAD as App

# the project's one palette (standard library only; the macro puts synthdet on sys.path)
from synthdet.classes import class_color

WALL_TRANSPARENCY = 75  # percent: the walls stay visible without hiding the room's contents
# FreeCAD's isometric view: camera x to the right along (1, 1, 0), looking along (-1, 1, -1)
ISOMETRIC = App.Rotation(App.Vector(1, 1, 0), App.Vector(-1, 1, 2), App.Vector(1, -1, 1), 'ZXY')
HIDDEN_TYPES = ('App::Origin', 'App::Line', 'App::Plane')
VIEW_MARGIN = 1.05


def _packed(rgb: tuple[int, int, int]) -> int:
    red, green, blue = rgb
    return (red << 24) | (green << 16) | (blue << 8)


class Look:
    """Colors (and transparency) of the document's solids, keyed by object name."""

    def __init__(self):
        self.colors: dict[str, tuple[tuple[int, int, int], int]] = {}

    def paint(self, obj, rgb: tuple[int, int, int], transparency: int = 0) -> None:
        """Give ``obj`` a color (0-255 RGB) and a transparency (percent)."""
        self.colors[obj.Name] = (tuple(rgb), transparency)

    def apply_in_gui(self, doc) -> None:
        """Color the view providers of ``doc`` in a running GUI and fit an isometric view."""
        import FreeCADGui as Gui

        for name, (rgb, transparency) in self.colors.items():
            obj = doc.getObject(name)
            view = obj.ViewObject
            color = tuple(value / 255.0 for value in rgb)
            view.ShapeColor = color
            view.Transparency = transparency
        gui_document = Gui.getDocument(doc.Name)
        view = gui_document.activeView()
        if view is not None and hasattr(view, 'viewIsometric'):
            view.viewIsometric()
            view.fitAll()

    def write_gui_document(self, path: str, doc) -> None:
        """Insert into the saved ``path`` the ``GuiDocument.xml`` the GUI would have written.

        Every object gets its stored visibility (origin helpers hidden), painted solids their
        color, and the camera an isometric view fitted to the visible shapes. FreeCAD reads
        the zip's files in the order it asks for them, so the new file goes after the
        document's own files (the shapes), where a GUI-saved document has it: appended, or, if
        the file already holds one, by writing the archive anew.
        """
        xml = self._gui_xml(doc)
        with zipfile.ZipFile(path) as source:
            has_gui_document = 'GuiDocument.xml' in source.namelist()
        if not has_gui_document:  # appending leaves the shapes as FreeCAD compressed them
            with zipfile.ZipFile(path, 'a', zipfile.ZIP_DEFLATED) as target:
                target.writestr('GuiDocument.xml', xml)
            return
        temporary = f'{path}.gui'  # beside ``path``, named after it: cleaned up with it
        try:
            with zipfile.ZipFile(path) as source, \
                    zipfile.ZipFile(temporary, 'w', zipfile.ZIP_DEFLATED) as target:
                for info in source.infolist():
                    if info.filename != 'GuiDocument.xml':
                        target.writestr(info, source.read(info.filename))
                target.writestr('GuiDocument.xml', xml)
            os.replace(temporary, path)
        finally:
            if os.path.exists(temporary):
                os.remove(temporary)

    def _gui_xml(self, doc) -> str:
        providers = []
        for obj in doc.Objects:
            visible = bool(obj.Visibility) and obj.TypeId not in HIDDEN_TYPES
            properties = [
                _property('Visibility', 'App::PropertyBool',
                          f'<Bool value="{"true" if visible else "false"}"/>')
            ]
            if obj.Name in self.colors:
                rgb, transparency = self.colors[obj.Name]
                properties.append(
                    _property('ShapeColor', 'App::PropertyColor',
                              f'<PropertyColor value="{_packed(rgb)}"/>'))
                properties.append(
                    _property('Transparency', 'App::PropertyPercent',
                              f'<Integer value="{int(transparency)}"/>'))
            providers.append(f'        <ViewProvider name={quoteattr(obj.Name)} expanded="0">\n'
                             f'            <Properties Count="{len(properties)}" '
                             f'TransientCount="0">\n{"".join(properties)}'
                             '            </Properties>\n        </ViewProvider>\n')
        camera = escape(isometric_camera(_visible_bounds(doc)), {'\n': '&#10;', '"': '&quot;'})
        return ("<?xml version='1.0' encoding='utf-8'?>\n<Document SchemaVersion=\"1\">\n"
                f'    <ViewProviderData Count="{len(providers)}">\n{"".join(providers)}'
                f'    </ViewProviderData>\n    <Camera settings="{camera}"/>\n</Document>\n')


def _property(name: str, type_name: str, value: str) -> str:
    return (f'                <Property name="{name}" type="{type_name}">\n'
            f'                    {value}\n                </Property>\n')


def _visible_bounds(doc):
    """World bounds of the visible solids (a shape's bounds include its own placement; that
    of the groups around it is added)."""
    bounds = App.BoundBox()
    for obj in doc.Objects:
        if obj.Visibility and obj.isDerivedFrom('Part::Feature') and not obj.Shape.isNull():
            parent = obj.getGlobalPlacement().multiply(obj.Placement.inverse())
            bounds.add(obj.Shape.BoundBox.transformed(parent.toMatrix()))
    return bounds


def isometric_camera(bounds) -> str:
    """An Open Inventor orthographic camera looking isometrically at ``bounds`` (all in view)."""
    if not bounds.isValid():
        bounds = App.BoundBox(-1000, -1000, 0, 1000, 1000, 1000)
    radius = VIEW_MARGIN * bounds.DiagonalLength / 2.0
    towards_viewer = ISOMETRIC.multVec(App.Vector(0, 0, 1))
    position = bounds.Center + towards_viewer * (2.0 * radius)
    axis, angle = ISOMETRIC.Axis, ISOMETRIC.Angle
    return ('OrthographicCamera {\n  viewportMapping ADJUST_CAMERA\n'
            f'  position {position.x:.4f} {position.y:.4f} {position.z:.4f}\n'
            f'  orientation {axis.x:.8f} {axis.y:.8f} {axis.z:.8f}  {angle:.8f}\n'
            f'  nearDistance {0.5 * radius:.4f}\n  farDistance {3.5 * radius:.4f}\n'
            f'  aspectRatio 1\n  focalDistance {2.0 * radius:.4f}\n'
            f'  height {2.0 * radius:.4f}\n\n}}\n')
