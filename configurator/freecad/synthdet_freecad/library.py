"""The CAD library: one parametric FreeCAD model per detection class.

Runs inside FreeCAD. Every detection is one object, a ``Part::FeaturePython`` whose proxy
(``DetectionModel``) builds its shape, a compound of solids, from the object's own properties:
``Length``, ``Width`` and ``Height`` (mm, along the local x, y and z axes) and the model's
details (group ``Dimensions``: a table's ``TopThickness``, a YuMi's ``Scale`` and joint angles,
...). Details that follow the main dimensions are FreeCAD expressions on the object
(``Height * 0.06``) until the user types a value. Its origin is the centre of its base (the
model stands on the part's z = 0 plane, so a height edit keeps its feet in place) and its front
is its local -y side. Edit a property, recompute, and the shape follows. The shape is stored
in the document, so any FreeCAD shows it; rebuilding it needs this module loaded before the
document opens (FreeCAD restores a proxy only from a module already loaded or an installed
add-on): run the macro once after FreeCAD starts, or import ``synthdet_freecad.library``.

One object per detection keeps building fast: no expression per solid (FreeCAD sets each in
about 80 microseconds) and one shape to store per detection, which ``archive.save_copy``
stores in linear time.

Object names are chosen here (``Chair001``), checked to be free: FreeCAD therefore does not
search the whole document for a free name (it does that for every name already taken, which
makes building n objects take time in n squared). Expressions are assembled only from fixed
property names and numbers: nothing read from the input files is ever part of one.
"""
import math

import FreeCAD as App
import Part

# class name -> (object base name, builder name); names are fixed identifiers, never user input
BUILTIN_MODELS = {
    'table': ('Table', 'table'),
    'chair': ('Chair', 'chair'),
    'sofa': ('Sofa', 'sofa'),
    'bookcase': ('Bookcase', 'bookcase'),
    'yumi': ('Yumi', 'yumi'),
    '3dprinter': ('Printer3D', 'printer'),
}
LABEL_COLUMN_WIDTH = 280  # pixels: the room sheet's description column shows whole text

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


PART_TYPE = 'Part::FeaturePython'
DIMENSIONS = 'Dimensions'  # the property group of a part's sizes and model details
# a model's details: property, description, expression on the part's own dimensions (what it
# follows until the user types a value); all lengths except the YuMi's Scale
DETAILS = {
    'table': (('TopThickness', 'top thickness', 'Height * 0.06'),
              ('LegSide', 'leg side', 'min(Length; Width) * 0.08')),
    'chair': (('SeatHeight', 'seat height', 'Height * 0.5'),
              ('SeatThickness', 'seat thickness', 'Height * 0.05'),
              ('LegSide', 'leg side', 'min(Length; Width) * 0.08'),
              ('BackrestThickness', 'backrest thickness', 'Width * 0.1')),
    'sofa': (('SeatHeight', 'seat height', 'Height * 0.55'),
             ('BackrestDepth', 'backrest depth', 'Width * 0.25'),
             ('ArmrestWidth', 'armrest width', 'Length * 0.1'),
             ('ArmrestHeight', 'armrest height', 'Height * 0.75')),
    'bookcase': (('BoardThickness', 'board thickness', 'min(Length; Width) * 0.06'),),
    'printer': (('BaseHeight', 'base height', 'Height * 0.12'),
                ('TopFrameThickness', 'top frame thickness', 'Height * 0.06'),
                ('PostSide', 'frame post side', 'min(Length; Width) * 0.06'),
                ('BedHeight', 'print bed height above the printer foot', 'Height * 0.4'),
                ('HeadSize', 'print head size', 'min(Length; Width) * 0.2')),
    'yumi': (('Scale', 'size relative to the real IRB 14000',
              f'min(Height / {1000 * YUMI_HEIGHT:g} mm; Width / {1000 * YUMI_REST_DEPTH:g} mm; '
              f'Length / {1000 * YUMI_REST_ACROSS:g} mm)'),),
}


def yumi_joint(side: str, joint: int) -> str:
    """The property of a YuMi joint angle: ``RightJoint2`` (ABB joint numbering)."""
    return f'{side.capitalize()}Joint{joint}'


def free_name(doc, base_name: str, next_numbers: dict[str, int]) -> str:
    """``<base_name><NNN>``, the first number from ``next_numbers[base_name]`` on (1 if absent)
    that is free in ``doc``; advances the counter, so that n names cost n look-ups, not the
    n squared of FreeCAD's own search."""
    number = next_numbers.get(base_name, 1)
    while doc.getObject(f'{base_name}{number:03d}') is not None:
        number += 1
    next_numbers[base_name] = number + 1
    return f'{base_name}{number:03d}'


def _box(length: float, width: float, height: float, x: float, y: float, z: float):
    """A solid box with its lower-left-bottom corner at (x, y, z)."""
    return Part.makeBox(length, width, height, App.Vector(x, y, z))


def _corner_posts(length: float, width: float, post: float, height: float, z: float) -> list:
    """Four square posts of side ``post`` in the corners of the length x width footprint."""
    return [
        _box(post, post, height, -length / 2 if sx < 0 else length / 2 - post,
             -width / 2 if sy < 0 else width / 2 - post, z)
        for sx, sy in ((-1, -1), (1, -1), (-1, 1), (1, 1))
    ]


def table_solids(p: dict) -> list:
    """Table: a top on four legs."""
    length, width, height, top = p['Length'], p['Width'], p['Height'], p['TopThickness']
    return [_box(length, width, top, -length / 2, -width / 2, height - top)] + \
        _corner_posts(length, width, p['LegSide'], height - top, 0.0)


def chair_solids(p: dict) -> list:
    """Chair: seat on four legs, backrest along the back (+y) edge."""
    length, width, height = p['Length'], p['Width'], p['Height']
    seat_height, seat, back = p['SeatHeight'], p['SeatThickness'], p['BackrestThickness']
    return [_box(length, width, seat, -length / 2, -width / 2, seat_height - seat)] + \
        _corner_posts(length, width, p['LegSide'], seat_height - seat, 0.0) + \
        [_box(length, back, height - seat_height, -length / 2, width / 2 - back, seat_height)]


def sofa_solids(p: dict) -> list:
    """Sofa: seat block between two armrests, backrest along the back (+y) edge."""
    length, width, height = p['Length'], p['Width'], p['Height']
    back, arm = p['BackrestDepth'], p['ArmrestWidth']
    return [
        _box(length - 2 * arm, width - back, p['SeatHeight'], -length / 2 + arm, -width / 2, 0.0),
        _box(length, back, height, -length / 2, width / 2 - back, 0.0)
    ] + [
        _box(arm, width - back, p['ArmrestHeight'], x, -width / 2, 0.0)
        for x in (-length / 2, length / 2 - arm)
    ]


def bookcase_solids(p: dict) -> list:
    """Bookcase: sides, bottom, top, back panel (+y) and three shelves."""
    length, width, height, board = p['Length'], p['Width'], p['Height'], p['BoardThickness']
    inner, left = length - 2 * board, -length / 2 + board
    solids = [_box(board, width, height, x, -width / 2, 0.0)
              for x in (-length / 2, length / 2 - board)]
    solids += [_box(inner, width, board, left, -width / 2, z) for z in (0.0, height - board)]
    solids.append(_box(inner, board, height - 2 * board, left, width / 2 - board, board))
    solids += [_box(inner, width - board, board, left, -width / 2, shelf * height / 4 - board / 2)
               for shelf in (1, 2, 3)]
    return solids


def printer_solids(p: dict) -> list:
    """3D printer: base, four frame posts, top frame, print bed and print head."""
    length, width, height = p['Length'], p['Width'], p['Height']
    base, top, head = p['BaseHeight'], p['TopFrameThickness'], p['HeadSize']
    return [_box(length, width, base, -length / 2, -width / 2, 0.0)] + \
        _corner_posts(length, width, p['PostSide'], height - base - top, base) + [
            _box(length, width, top, -length / 2, -width / 2, height - top),
            _box(length * 0.7, width * 0.7, base * 0.3, -length * 0.35, -width * 0.35,
                 p['BedHeight']),
            _box(head, head, head, -head / 2, -head / 2, height - top - head)]


def _pose(scale: float, xyz: tuple[float, float, float], rpy: tuple[float, float, float]):
    """A fixed placement (robot metres scaled to mm by ``scale``, roll-pitch-yaw radians)."""
    roll, pitch, yaw = (math.degrees(angle) for angle in rpy)
    return App.Placement(App.Vector(*(1000.0 * scale * value for value in xyz)),
                         App.Rotation(yaw, pitch, roll))


def _spin(degrees: float):
    """A rotation about the local z axis."""
    return App.Placement(App.Vector(), App.Rotation(App.Vector(0, 0, 1), degrees))


def yumi_arm_frames(p: dict, side: str) -> list:
    """The placements (part frame, mm) of the 7 links of one arm, after each joint in ABB's
    order 1, 2, 7, 3, 4, 5, 6 along the arm."""
    scale = p['Scale']
    robot = App.Placement(App.Vector(0, 1000.0 * scale * YUMI_REST_FORWARD, 0),
                          App.Rotation(-90, 0, 0))  # robot x forward -> the part's -y
    frame = robot.multiply(_pose(scale, *YUMI_SHOULDER[side]))
    frames = []
    for position, joint in enumerate(YUMI_JOINT_ORDER):
        if position > 0:
            frame = frame.multiply(_pose(scale, *YUMI_CHAIN[position - 1]))
        frame = frame.multiply(_spin(p[yumi_joint(side, joint)]))
        frames.append(frame)
    return frames


def yumi_solids(p: dict) -> list:
    """ABB YuMi (IRB 14000): base plate, tapered body (three wedges), and per arm (right, then
    left) seven cylinder links and a gripper box: 20 solids, the real robot's geometry scaled
    uniformly by ``Scale``, facing -y, posed by the joint angles."""
    scale = p['Scale']

    def mm(metres: float) -> float:
        return 1000.0 * scale * metres

    robot = App.Placement(App.Vector(0, mm(YUMI_REST_FORWARD), 0), App.Rotation(-90, 0, 0))
    depth, across, plate = YUMI_BASE
    solids = [_box(mm(across), mm(depth), mm(plate), -mm(across / 2),
                   mm(YUMI_REST_FORWARD - depth / 2), 0.0)]
    upright = robot.multiply(App.Placement(App.Vector(), App.Rotation(0, 0, 90)))
    for low, high in zip(YUMI_TORSO, YUMI_TORSO[1:]):  # wedge y (its taper) along robot z
        wedge = Part.makeWedge(mm(low[1]), mm(low[0]), -mm(low[3]), -mm(high[3]), mm(high[1]),
                               mm(low[2]), mm(high[0]), mm(low[3]), mm(high[3]), mm(high[2]))
        wedge.Placement = upright
        solids.append(wedge)
    offsets = [xyz for xyz, _ in YUMI_CHAIN] + [(0.0, 0.0, YUMI_FLANGE)]
    for side in ('right', 'left'):
        frames = yumi_arm_frames(p, side)
        for frame, offset, radius in zip(frames, offsets, YUMI_LINK_RADII):
            link = Part.makeCylinder(mm(radius), mm(math.sqrt(sum(v * v for v in offset))))
            link.Placement = frame.multiply(
                App.Placement(App.Vector(), App.Rotation(App.Vector(0, 0, 1),
                                                         App.Vector(*offset))))
            solids.append(link)
        size_x, size_y, size_z = YUMI_GRIPPER
        gripper = Part.makeBox(mm(size_x), mm(size_y), mm(size_z))
        gripper.Placement = frames[-1].multiply(
            App.Placement(App.Vector(-mm(size_x / 2), -mm(size_y / 2), mm(YUMI_FLANGE)),
                          App.Rotation()))
        solids.append(gripper)
    return solids


def box_solids(p: dict) -> list:
    """Placeholder for a class without a model: the detection box itself."""
    return [_box(p['Length'], p['Width'], p['Height'], -p['Length'] / 2, -p['Width'] / 2, 0.0)]


def step_shape(p: dict, library_object):
    """A user STEP shape scaled per axis to fill the box, its base centred on the origin."""
    shape = library_object.Shape
    bound = shape.BoundBox
    scales = [size / max(extent, 1e-3) for size, extent in
              ((p['Length'], bound.XLength), (p['Width'], bound.YLength),
               (p['Height'], bound.ZLength))]
    matrix = App.Matrix()
    matrix.scale(*scales)
    matrix.move(App.Vector(-scales[0] * bound.Center.x, -scales[1] * bound.Center.y,
                           -scales[2] * bound.Center.z + p['Height'] / 2))
    return shape.transformGeometry(matrix)


BUILDERS = {
    'table': table_solids,
    'chair': chair_solids,
    'sofa': sofa_solids,
    'bookcase': bookcase_solids,
    'yumi': yumi_solids,
    'printer': printer_solids,
}


def model_parameters(obj) -> dict:
    """The part's ``Dimensions`` properties as plain numbers (mm, degrees, the YuMi's scale)."""
    values = {}
    for name in obj.PropertiesList:
        if obj.getGroupOfProperty(name) == DIMENSIONS:
            value = getattr(obj, name)
            values[name] = float(getattr(value, 'Value', value))
    return values


def model_shape(obj):
    """The part's shape in its own frame: the compound of its model's solids."""
    parameters = model_parameters(obj)
    if obj.CadModel == 'step':
        if obj.StepModel is None:
            raise ValueError(f'{obj.Label}: its STEP model is gone')
        return step_shape(parameters, obj.StepModel)
    if obj.CadModel == 'builtin' and obj.DetectedClass in BUILTIN_MODELS:
        solids = BUILDERS[BUILTIN_MODELS[obj.DetectedClass][1]](parameters)
    else:
        solids = box_solids(parameters)
    return Part.makeCompound(solids)


class DetectionModel:
    """The proxy of a detection's part: builds its shape from its properties. It keeps no
    state of its own (nothing is serialised)."""

    def __init__(self, obj):
        obj.Proxy = self

    def execute(self, obj) -> None:
        """Recompute: the model's solids, at the part's placement."""
        obj.Shape = model_shape(obj)

    # the state FreeCAD stores: none (FreeCAD 0.20 asks __getstate__, later ones dumps)
    def __getstate__(self):
        return None

    def __setstate__(self, state) -> None:
        return None

    dumps = __getstate__
    loads = __setstate__


def restore_proxies(doc) -> int:
    """Give back their proxy to the parts of ``doc`` that were restored without it (opened
    while this module was not loaded, then saved); returns how many."""
    restored = 0
    for obj in doc.Objects:
        if obj.TypeId == PART_TYPE and 'DetectedClass' in obj.PropertiesList and \
                obj.Proxy is None:
            DetectionModel(obj)
            restored += 1
    return restored


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
    """Create one placed detection's parametric part; returns (part, model kind).

    ``placed`` is an ``arrangement.Placed``: label, pose and dimensions in metres.
    ``library_object`` is the imported user STEP shape for the class, if any; otherwise the
    built-in model is used, or a plain box for classes without one. ``next_numbers`` (base
    name -> next number, see ``free_name``) is shared by the calls of one import. The shape is
    built by the next recompute.
    """
    class_name = placed.class_name
    base_name, builder = BUILTIN_MODELS.get(class_name, ('Detection', None))
    if library_object is not None:
        kind = 'step'
    else:
        kind = 'builtin' if builder else 'box'
    numbers = {} if next_numbers is None else next_numbers
    part = doc.addObject(PART_TYPE, free_name(doc, base_name, numbers))
    DetectionModel(part)
    part.Label = placed.label
    for prop, type_name, doc_text in SYNTHDET_PROPERTIES:
        part.addProperty(type_name, prop, 'Synthdet', doc_text)
    part.DetectedClass = class_name
    part.Score = placed.detection['score']
    part.SourceScan = scan
    part.SourceModel = model_name
    part.CadModel = kind
    part.DetectedYaw = math.degrees(placed.detection['yaw'])
    part.Orientation = placed.orientation
    part.StandsOn = placed.support.label if placed.support is not None else 'floor'
    for prop, axis, metres in (('Length', 'x', placed.length), ('Width', 'y', placed.width),
                               ('Height', 'z', placed.height)):
        part.addProperty('App::PropertyLength', prop, DIMENSIONS,
                         f'{prop.lower()} (along the local {axis} axis)')
        setattr(part, prop, 1000.0 * metres)
    if kind == 'step':
        part.addProperty('App::PropertyLink', 'StepModel', 'Synthdet',
                         'the imported STEP model, scaled to the dimensions')
        part.StepModel = library_object
    elif kind == 'builtin':
        _add_details(part, builder)
    base = App.Vector(1000.0 * placed.x, 1000.0 * placed.y, 1000.0 * placed.base_z)
    part.Placement = App.Placement(base,
                                   App.Rotation(App.Vector(0, 0, 1), math.degrees(placed.yaw)))
    return part, kind


def _add_details(part, builder: str) -> None:
    """The built-in model's detail properties (bound to the dimensions by expressions) and,
    for the YuMi, its joint angles in the rest pose."""
    for prop, description, expression in DETAILS.get(builder, ()):
        type_name = 'App::PropertyFloat' if prop == 'Scale' else 'App::PropertyLength'
        part.addProperty(type_name, prop, DIMENSIONS, f'{description} (follows the dimensions '
                         'until a value is typed)')
        part.setExpression(prop, expression)
    if builder == 'yumi':
        for side in ('right', 'left'):
            for joint in (1, 2, 3, 4, 5, 6, 7):
                angle = YUMI_REST_DEG[joint] * (-1 if side == 'left' and joint in YUMI_MIRRORED
                                                else 1)
                prop = yumi_joint(side, joint)
                part.addProperty('App::PropertyAngle', prop, DIMENSIONS,
                                 f'{side} arm joint {joint} angle (ABB numbering)')
                setattr(part, prop, angle)
