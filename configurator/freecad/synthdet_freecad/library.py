"""The CAD library: one natively parametric FreeCAD model per detection class.

Runs inside FreeCAD. Every model is one ``App::LinkGroup`` (a group with a placement, without
the origin and its six axes and planes every ``App::Part`` creates), which draws its solids at
its placement (they are hidden themselves), whose origin is the centre of its base (the model
stands on the part's z = 0 plane, so a height edit keeps its feet in place) and whose front is
its local -y side. Its dimensions sit in a ``Spreadsheet::Sheet`` inside that part (aliases
``length``, ``width``, ``height`` in mm along the local x, y, z axes, plus model details such
as the YuMi joint angles), and every solid is bound to those cells by FreeCAD expressions. The
document therefore stays parametric in a plain FreeCAD: edit a cell, recompute, and the
geometry follows. No Python feature proxies are used.

Object names are chosen here (``Chair001``, ``Chair001_Seat``, ``Chair001_Parameters``): the
part's and its sheet's are checked to be free, its solids' start with the part's. FreeCAD
therefore does not search the whole document for a free name (it does that for every name
already taken, which makes building n objects take time in n squared).
Expressions are assembled only from those names, built from fixed base names, cell aliases
defined here, and numbers: nothing read from the input files is ever part of one.
"""
import math
import re

import FreeCAD as App

# class name -> (object base name, builder name); names are fixed identifiers, never user input
BUILTIN_MODELS = {
    'table': ('Table', 'table'),
    'chair': ('Chair', 'chair'),
    'sofa': ('Sofa', 'sofa'),
    'bookcase': ('Bookcase', 'bookcase'),
    'yumi': ('Yumi', 'yumi'),
    '3dprinter': ('Printer3D', 'printer'),
}
LABEL_COLUMN_WIDTH = 280  # pixels: the sheets' description column shows whole descriptions

# ABB IRB 14000 (YuMi), the facts generator/assets/yumi.py builds its meshes from (ABB product
# specification; public URDF descriptions): robot frame x forward, y left, z up, metres, angles
# in radians; joints along an arm in ABB's order 1, 2, 7, 3, 4, 5, 6.
YUMI_HEIGHT = 0.571
# the extent of this model in its rest pose: across (robot y) and along (robot x: from the
# grippers in front, 0.389 m, to the base plate's back, 0.2485 m) -- the box it is fitted to
YUMI_REST_ACROSS = 0.532
YUMI_REST_DEPTH = 0.638
YUMI_REST_FORWARD = 0.07025  # how far the rest pose's footprint centre lies ahead of the base
YUMI_BASE = (0.497, 0.399, 0.08)
YUMI_TORSO = ((0.08, -0.22, 0.20, 0.18), (0.30, -0.18, 0.10, 0.14), (0.48, -0.15, 0.045, 0.085),
              (0.571, -0.13, 0.0, 0.06))  # cross-sections: z, x back, x front, half width
YUMI_JOINT_ORDER = (1, 2, 7, 3, 4, 5, 6)
YUMI_SHOULDER = {
    'right': ((0.05355, -0.0725, 0.41492), (-0.9795, -0.5682, -2.3155)),
    'left': ((0.05355, 0.0725, 0.41492), (0.9781, -0.5716, 2.3180))
}
YUMI_CHAIN = (((0.03, 0.0, 0.1), (math.pi / 2, 0.0, 0.0)), ((-0.03, 0.17283, 0.0), (-math.pi / 2,
                                                                                    0.0, 0.0)),
              ((-0.04188, 0.0, 0.07873), (math.pi / 2, -math.pi / 2, 0.0)),
              ((0.0405, 0.16461, 0.0), (-math.pi / 2, 0.0, 0.0)),
              ((-0.027, 0.0, 0.10039), (math.pi / 2, 0.0, 0.0)), ((0.027, 0.029, 0.0),
                                                                  (-math.pi / 2, 0.0, 0.0)))
YUMI_LINK_RADII = (0.045, 0.042, 0.04, 0.038, 0.034, 0.03, 0.028)
YUMI_FLANGE = 0.03
YUMI_GRIPPER = (0.09, 0.05, 0.12)  # beyond the flange
# The folded rest pose (right arm, degrees, by ABB joint number); the left arm mirrors it with
# joints 1, 7, 4 and 6 negated.
YUMI_REST_DEG = {1: 88.0, 2: -129.0, 7: -69.0, 3: 76.0, 4: 193.0, 5: 118.0, 6: -115.0}
YUMI_MIRRORED = (1, 7, 4, 6)


def _readable(suffix: str) -> str:
    """``LegFrontLeft`` -> ``leg front left``, ``RightLink3`` -> ``right link 3``."""
    return ' '.join(word.lower() for word in re.findall(r'[A-Z][a-z]*|[0-9]+', suffix))


CONTAINER_TYPE = 'App::LinkGroup'
SHEET_SUFFIX = '_Parameters'


def children(container) -> list:
    """The objects a detection's part holds: its parameter sheet first, then its solids."""
    return list(container.ElementList)


def parameter_sheet(container):
    """The ``Spreadsheet::Sheet`` holding a detection part's dimensions."""
    return container.Document.getObject(container.Name + SHEET_SUFFIX)


def free_name(doc, base_name: str, next_numbers: dict[str, int]) -> str:
    """``<base_name><NNN>``, the first number from ``next_numbers[base_name]`` on (1 if absent)
    whose part and parameter sheet names are both free in ``doc``; advances the counter, so that
    n names cost n look-ups, not the n squared of FreeCAD's own search."""
    number = next_numbers.get(base_name, 1)
    while doc.getObject(f'{base_name}{number:03d}') is not None or \
            doc.getObject(f'{base_name}{number:03d}{SHEET_SUFFIX}') is not None:
        number += 1
    next_numbers[base_name] = number + 1
    return f'{base_name}{number:03d}'


class ModelBuilder:
    """Adds expression-bound solids to one detection's part (collected, then set at once)."""

    def __init__(self, doc, container, sheet):
        self.doc = doc
        self.container = container
        self.sheet = sheet
        self.row = 1
        self.children = [sheet]

    def parameter(self, alias: str, value: str, description: str) -> None:
        """Add a sheet row: description in column A, the value (aliased) in column B."""
        self.sheet.set(f'A{self.row}', description)
        self.sheet.set(f'B{self.row}', value)
        self.sheet.setAlias(f'B{self.row}', alias)
        self.row += 1

    def expr(self, template: str) -> str:
        """Expand ``{P}`` in an expression template to this model's sheet name."""
        return template.replace('{P}', self.sheet.Name)

    def _add(self, type_name: str, suffix: str):
        obj = self.doc.addObject(type_name, f'{self.container.Name}_{suffix}')
        obj.Label = f'{self.container.Label} {_readable(suffix)}'
        self.children.append(obj)
        return obj

    def _bind(self, obj, values: dict) -> None:
        for prop, template in values.items():
            obj.setExpression(prop, self.expr(template))

    def box(self, suffix: str, length: str, width: str, height: str, x: str, y: str, z: str):
        """A ``Part::Box`` with expression-bound size and lower-left-bottom corner."""
        obj = self._add('Part::Box', suffix)
        self._bind(
            obj, {
                'Length': length,
                'Width': width,
                'Height': height,
                '.Placement.Base.x': x,
                '.Placement.Base.y': y,
                '.Placement.Base.z': z
            })
        return obj

    def solid(self, type_name: str, suffix: str, values: dict):
        """Any primitive (``Part::Cylinder``, ``Part::Wedge``, ...) with bound properties."""
        obj = self._add(type_name, suffix)
        self._bind(obj, values)
        return obj


def _corner_posts(model: ModelBuilder, name: str, post: str, height: str, z: str) -> None:
    """Four square posts of side ``post`` in the corners of the length x width footprint."""
    for sx, sy, where in ((-1, -1, 'FrontLeft'), (1, -1, 'FrontRight'), (-1, 1, 'BackLeft'),
                          (1, 1, 'BackRight')):
        x = '-{P}.length / 2' if sx < 0 else '{P}.length / 2 - ' + post
        y = '-{P}.width / 2' if sy < 0 else '{P}.width / 2 - ' + post
        model.box(f'{name}{where}', post, post, height, x, y, z)


def build_table(model: ModelBuilder) -> None:
    """Table: a top on four legs."""
    model.parameter('top', '=height * 0.06', 'top thickness')
    model.parameter('leg', '=min(length; width) * 0.08', 'leg side')
    model.box('Top', '{P}.length', '{P}.width', '{P}.top', '-{P}.length / 2', '-{P}.width / 2',
              '{P}.height - {P}.top')
    _corner_posts(model, 'Leg', '{P}.leg', '{P}.height - {P}.top', '0 mm')


def build_chair(model: ModelBuilder) -> None:
    """Chair: seat on four legs, backrest along the back (+y) edge."""
    model.parameter('seat_height', '=height * 0.5', 'seat height')
    model.parameter('seat', '=height * 0.05', 'seat thickness')
    model.parameter('leg', '=min(length; width) * 0.08', 'leg side')
    model.parameter('back', '=width * 0.1', 'backrest thickness')
    model.box('Seat', '{P}.length', '{P}.width', '{P}.seat', '-{P}.length / 2', '-{P}.width / 2',
              '{P}.seat_height - {P}.seat')
    _corner_posts(model, 'Leg', '{P}.leg', '{P}.seat_height - {P}.seat', '0 mm')
    model.box('Backrest', '{P}.length', '{P}.back', '{P}.height - {P}.seat_height',
              '-{P}.length / 2', '{P}.width / 2 - {P}.back', '{P}.seat_height')


def build_sofa(model: ModelBuilder) -> None:
    """Sofa: seat block between two armrests, backrest along the back (+y) edge."""
    model.parameter('seat_height', '=height * 0.55', 'seat height')
    model.parameter('back', '=width * 0.25', 'backrest depth')
    model.parameter('arm', '=length * 0.1', 'armrest width')
    model.parameter('arm_height', '=height * 0.75', 'armrest height')
    model.box('Seat', '{P}.length - 2 * {P}.arm', '{P}.width - {P}.back', '{P}.seat_height',
              '-{P}.length / 2 + {P}.arm', '-{P}.width / 2', '0 mm')
    model.box('Backrest', '{P}.length', '{P}.back', '{P}.height', '-{P}.length / 2',
              '{P}.width / 2 - {P}.back', '0 mm')
    for suffix, x in (('ArmrestLeft', '-{P}.length / 2'), ('ArmrestRight',
                                                           '{P}.length / 2 - {P}.arm')):
        model.box(suffix, '{P}.arm', '{P}.width - {P}.back', '{P}.arm_height', x, '-{P}.width / 2',
                  '0 mm')


def build_bookcase(model: ModelBuilder) -> None:
    """Bookcase: sides, top, bottom, back panel (+y) and three shelves."""
    model.parameter('board', '=min(length; width) * 0.06', 'board thickness')
    inner = '{P}.length - 2 * {P}.board'
    for suffix, x in (('SideLeft', '-{P}.length / 2'), ('SideRight',
                                                        '{P}.length / 2 - {P}.board')):
        model.box(suffix, '{P}.board', '{P}.width', '{P}.height', x, '-{P}.width / 2', '0 mm')
    for suffix, z in (('Bottom', '0 mm'), ('Top', '{P}.height - {P}.board')):
        model.box(suffix, inner, '{P}.width', '{P}.board', '-{P}.length / 2 + {P}.board',
                  '-{P}.width / 2', z)
    model.box('Back', inner, '{P}.board', '{P}.height - 2 * {P}.board',
              '-{P}.length / 2 + {P}.board', '{P}.width / 2 - {P}.board', '{P}.board')
    for shelf in (1, 2, 3):
        model.box(f'Shelf{shelf}', inner, '{P}.width - {P}.board', '{P}.board',
                  '-{P}.length / 2 + {P}.board', '-{P}.width / 2',
                  f'{shelf} * {{P}}.height / 4 - {{P}}.board / 2')


def build_printer(model: ModelBuilder) -> None:
    """3D printer: base, four frame posts, top frame, print bed and print head."""
    model.parameter('base', '=height * 0.12', 'base height')
    model.parameter('top', '=height * 0.06', 'top frame thickness')
    model.parameter('post', '=min(length; width) * 0.06', 'frame post side')
    model.parameter('bed_height', '=height * 0.4', 'print bed height above the printer foot')
    model.parameter('head', '=min(length; width) * 0.2', 'print head size')
    model.box('Base', '{P}.length', '{P}.width', '{P}.base', '-{P}.length / 2', '-{P}.width / 2',
              '0 mm')
    _corner_posts(model, 'Post', '{P}.post', '{P}.height - {P}.base - {P}.top', '{P}.base')
    model.box('TopFrame', '{P}.length', '{P}.width', '{P}.top', '-{P}.length / 2',
              '-{P}.width / 2', '{P}.height - {P}.top')
    model.box('Bed', '{P}.length * 0.7', '{P}.width * 0.7', '{P}.base * 0.3', '-{P}.length * 0.35',
              '-{P}.width * 0.35', '{P}.bed_height')
    model.box('Head', '{P}.head', '{P}.head', '{P}.head', '-{P}.head / 2', '-{P}.head / 2',
              '{P}.height - {P}.top - {P}.head')


def _mm(metres: float) -> str:
    """A robot-frame length scaled by the model's ``scale`` cell."""
    return f'{1000.0 * metres:.4f} mm * {{P}}.scale'


def _pose(xyz: tuple[float, float, float], rpy: tuple[float, float, float]) -> str:
    """A fixed placement (robot metres, roll-pitch-yaw radians) as an expression."""
    roll, pitch, yaw = (math.degrees(angle) for angle in rpy)
    return (f'create(<<placement>>; create(<<vector>>; {_mm(xyz[0])}; {_mm(xyz[1])}; '
            f'{_mm(xyz[2])}); create(<<rotation>>; {yaw:.6f}; {pitch:.6f}; {roll:.6f}))')


def _spin(angle: str) -> str:
    """A rotation about the local z axis by the angle expression ``angle``."""
    return ('create(<<placement>>; create(<<vector>>; 0 mm; 0 mm; 0 mm); '
            f'create(<<rotation>>; create(<<vector>>; 0; 0; 1); {angle}))')


def _z_to(direction: tuple[float, float, float]) -> str:
    """A rotation turning the local z axis onto ``direction`` (for a link's cylinder)."""
    rotation = App.Rotation(App.Vector(0, 0, 1), App.Vector(*direction))
    yaw, pitch, roll = rotation.toEuler()
    return (f'create(<<placement>>; create(<<vector>>; 0 mm; 0 mm; 0 mm); '
            f'create(<<rotation>>; {yaw:.6f}; {pitch:.6f}; {roll:.6f}))')


def build_yumi(model: ModelBuilder) -> None:
    """ABB YuMi (IRB 14000): a tapered body on its base plate and two 7-axis arms.

    The real robot's geometry scaled uniformly by ``scale`` (fit to the box), facing -y. Joint
    angles ``right_joint_N``/``left_joint_N`` (ABB numbering) default to a folded rest pose;
    each arm frame (``right_frame_K``, K along the arm) is a placement cell computed from them.
    """
    model.parameter(
        'scale', f'=min(height / {1000 * YUMI_HEIGHT} mm; width / '
        f'{1000 * YUMI_REST_DEPTH} mm; length / {1000 * YUMI_REST_ACROSS} mm)',
        'size relative to the real IRB 14000')
    for side in ('right', 'left'):
        for joint in (1, 2, 3, 4, 5, 6, 7):
            angle = YUMI_REST_DEG[joint] * (-1 if side == 'left' and joint in YUMI_MIRRORED else 1)
            model.parameter(f'{side}_joint_{joint}', f'={angle:g} deg',
                            f'{side} arm joint {joint} angle')
    # robot frame (x forward) -> part frame (the robot faces -y, its rest pose centred)
    robot = (f'create(<<placement>>; create(<<vector>>; 0 mm; {_mm(YUMI_REST_FORWARD)}; 0 mm); '
             'create(<<rotation>>; -90; 0; 0))')
    depth, across, plate = YUMI_BASE
    model.box('BasePlate', _mm(across), _mm(depth), _mm(plate), f'-{_mm(across / 2)}',
              f'{_mm(YUMI_REST_FORWARD - depth / 2)}', '0 mm')
    upright = f'{robot} * create(<<placement>>; create(<<vector>>; 0 mm; 0 mm; 0 mm); ' \
              'create(<<rotation>>; 0; 0; 90))'  # wedge y (its taper) along the robot's z
    for index, (low, high) in enumerate(zip(YUMI_TORSO, YUMI_TORSO[1:]), start=1):
        model.solid(
            'Part::Wedge', f'Body{index}', {
                'Placement': upright,
                'Ymin': _mm(low[0]),
                'Ymax': _mm(high[0]),
                'Xmin': _mm(low[1]),
                'Xmax': _mm(low[2]),
                'X2min': _mm(high[1]),
                'X2max': _mm(high[2]),
                'Zmin': f'-{_mm(low[3])}',
                'Zmax': _mm(low[3]),
                'Z2min': f'-{_mm(high[3])}',
                'Z2max': _mm(high[3])
            })
    for side in ('right', 'left'):
        title = side.capitalize()
        frame = f'{robot} * {_pose(*YUMI_SHOULDER[side])} * {_spin("{P}." + side + "_joint_1")}'
        offsets = [xyz for xyz, _ in YUMI_CHAIN] + [(0.0, 0.0, YUMI_FLANGE)]
        for position, joint in enumerate(YUMI_JOINT_ORDER, start=1):
            if position > 1:
                fixed = YUMI_CHAIN[position - 2]
                frame = (f'{{P}}.{side}_frame_{position - 1} * {_pose(*fixed)} * '
                         f'{_spin(f"{{P}}.{side}_joint_{joint}")}')
            model.parameter(f'{side}_frame_{position}', '=' + model.expr(frame),
                            f'{side} arm frame {position} (after joint {joint}; computed)')
            offset = offsets[position - 1]
            length = math.sqrt(sum(value * value for value in offset))
            model.solid(
                'Part::Cylinder', f'{title}Link{position}', {
                    'Placement': f'{{P}}.{side}_frame_{position} * {_z_to(offset)}',
                    'Radius': _mm(YUMI_LINK_RADII[position - 1]),
                    'Height': _mm(length)
                })
        size_x, size_y, size_z = YUMI_GRIPPER
        model.solid(
            'Part::Box', f'{title}Gripper', {
                'Placement':
                f'{{P}}.{side}_frame_7 * create(<<placement>>; create(<<vector>>; '
                f'-{_mm(size_x / 2)}; -{_mm(size_y / 2)}; {_mm(YUMI_FLANGE)}); '
                'create(<<rotation>>; 0; 0; 0))',
                'Length':
                _mm(size_x),
                'Width':
                _mm(size_y),
                'Height':
                _mm(size_z)
            })


def build_box(model: ModelBuilder) -> None:
    """Placeholder for a class without a model: the detection box itself."""
    model.box('Box', '{P}.length', '{P}.width', '{P}.height', '-{P}.length / 2', '-{P}.width / 2',
              '0 mm')


def build_step(model: ModelBuilder, library_object) -> None:
    """A user STEP shape, linked (``App::Link``) and scaled per axis to fill the box."""
    bound = library_object.Shape.BoundBox
    for axis, dimension, size, centre in (('x', 'length', bound.XLength, bound.Center.x),
                                          ('y', 'width', bound.YLength, bound.Center.y),
                                          ('z', 'height', bound.ZLength, bound.Center.z)):
        model.parameter(f'step_{dimension}', f'={max(size, 1e-3):.6f} mm',
                        f'STEP model {dimension}')
        model.parameter(f'step_centre_{axis}', f'={centre:.6f} mm', f'STEP model centre {axis}')
    link = model.doc.addObject('App::Link', f'{model.container.Name}_Model')
    link.Label = f'{model.container.Label} model'
    link.LinkedObject = library_object
    model.children.append(link)
    scale = ['{P}.%s / {P}.step_%s' % (name, name) for name in ('length', 'width', 'height')]
    link.setExpression('ScaleVector', model.expr(f'create(<<vector>>; {"; ".join(scale)})'))
    for axis, factor in zip('xyz', scale):
        lift = ' + {P}.height / 2' if axis == 'z' else ''
        link.setExpression(f'.Placement.Base.{axis}',
                           model.expr(f'-{factor} * {{P}}.step_centre_{axis}{lift}'))


BUILDERS = {
    'table': build_table,
    'chair': build_chair,
    'sofa': build_sofa,
    'bookcase': build_bookcase,
    'yumi': build_yumi,
    'printer': build_printer,
}
SYNTHDET_PROPERTIES = (
    ('DetectedClass', 'App::PropertyString', 'class predicted by the detector'),
    ('Score', 'App::PropertyFloat', 'detection confidence'),
    ('SourceScan', 'App::PropertyString', 'scan the detection came from'),
    ('SourceModel', 'App::PropertyString', 'detector that produced it'),
    ('CadModel', 'App::PropertyString', 'builtin, step or box (no model for the class)'),
    ('DetectedYaw', 'App::PropertyAngle', 'yaw of the detected box'),
    ('Orientation', 'App::PropertyString',
     'why the part faces where it does: the detection yaw or the rule for an axis-aligned '
     'detection (edit the placement angle to turn it)'),
    ('StandsOn', 'App::PropertyString', 'the floor or the table the part stands on'),
)


def add_detection(doc,
                  placed,
                  scan: str,
                  model_name: str,
                  library_object=None,
                  next_numbers: dict[str, int] | None = None):
    """Create one placed detection's parametric model; returns (container, model kind).

    ``placed`` is an ``arrangement.Placed``: label, pose and dimensions in metres.
    ``library_object`` is the imported user STEP shape for the class, if any; otherwise the
    built-in model is used, or a plain box for classes without one. ``next_numbers`` (base
    name -> next number, see ``free_name``) is shared by the calls of one import.
    """
    class_name = placed.class_name
    base_name, builder = BUILTIN_MODELS.get(class_name, ('Detection', None))
    if library_object is not None:
        kind = 'step'
    else:
        kind = 'builtin' if builder else 'box'
    numbers = {} if next_numbers is None else next_numbers
    container = doc.addObject(CONTAINER_TYPE, free_name(doc, base_name, numbers))
    container.Label = placed.label
    for prop, type_name, doc_text in SYNTHDET_PROPERTIES:
        container.addProperty(type_name, prop, 'Synthdet', doc_text)
    container.DetectedClass = class_name
    container.Score = placed.detection['score']
    container.SourceScan = scan
    container.SourceModel = model_name
    container.CadModel = kind
    container.DetectedYaw = math.degrees(placed.detection['yaw'])
    container.Orientation = placed.orientation
    container.StandsOn = placed.support.label if placed.support is not None else 'floor'
    base = App.Vector(1000.0 * placed.x, 1000.0 * placed.y, 1000.0 * placed.base_z)
    container.Placement = App.Placement(
        base, App.Rotation(App.Vector(0, 0, 1), math.degrees(placed.yaw)))
    sheet = doc.addObject('Spreadsheet::Sheet', container.Name + SHEET_SUFFIX)
    sheet.Label = f'{placed.label} parameters'
    sheet.setColumnWidth('A', LABEL_COLUMN_WIDTH)
    model = ModelBuilder(doc, container, sheet)
    for alias, value in zip(('length', 'width', 'height'),
                            (placed.length, placed.width, placed.height)):
        model.parameter(alias, f'={1000.0 * value:.3f} mm', alias)
    if kind == 'step':
        build_step(model, library_object)
    elif kind == 'builtin':
        BUILDERS[builder](model)
    else:
        build_box(model)
    for child in model.children:  # drawn by the part, at its placement, not on their own
        child.Visibility = False
    container.ElementList = model.children
    return container, kind
