"""The CAD library: one natively parametric FreeCAD model per detection class.

Runs inside FreeCAD. Every model lives in an ``App::Part`` whose placement is the detection box
centre (yaw about z). Its dimensions sit in a ``Spreadsheet::Sheet`` inside that part (aliases
``length``, ``width``, ``height`` in mm along the local x, y, z axes, plus model details such as
the YuMi joint angles), and every primitive is bound to those cells by FreeCAD expressions. The
document therefore stays parametric in a plain FreeCAD: edit a cell, recompute, and the geometry
follows. No Python feature proxies are used.

Expressions are assembled only from object names FreeCAD generated from fixed base names, cell
aliases defined here, and numbers: nothing read from the input files is ever part of one.
"""
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
YUMI_JOINTS = 7
YUMI_JOINT_AXES = ('z', 'y', 'z', 'y', 'z', 'y', 'z')
YUMI_LINKS = ('short', 'upper', 'short', 'upper', 'short', 'lower', 'short')
_AXIS_VECTORS = {'x': '1; 0; 0', 'y': '0; 1; 0', 'z': '0; 0; 1'}


class ModelBuilder:
    """Adds expression-bound primitives to one detection's ``App::Part``."""

    def __init__(self, doc, container, sheet):
        self.doc = doc
        self.container = container
        self.sheet = sheet
        self.row = 1

    def parameter(self, alias: str, value: str, description: str) -> None:
        """Add a sheet row: description in column A, the value (aliased) in column B."""
        self.sheet.set(f'A{self.row}', description)
        self.sheet.set(f'B{self.row}', value)
        self.sheet.setAlias(f'B{self.row}', alias)
        self.row += 1

    def expr(self, template: str) -> str:
        """Expand ``{P}`` in an expression template to this model's sheet name."""
        return template.replace('{P}', self.sheet.Name)

    def _add(self, type_name: str, suffix: str, parent):
        obj = self.doc.addObject(type_name, f'{self.container.Name}_{suffix}')
        (parent or self.container).addObject(obj)
        return obj

    def _place(self, obj, x: str, y: str, z: str) -> None:
        for axis, template in zip('xyz', (x, y, z)):
            obj.setExpression(f'.Placement.Base.{axis}', self.expr(template))

    def box(self,
            suffix: str,
            length: str,
            width: str,
            height: str,
            x: str,
            y: str,
            z: str,
            parent=None):
        """A ``Part::Box`` with expression-bound size and lower-left-bottom corner."""
        obj = self._add('Part::Box', suffix, parent)
        for prop, template in (('Length', length), ('Width', width), ('Height', height)):
            obj.setExpression(prop, self.expr(template))
        self._place(obj, x, y, z)
        return obj

    def cylinder(self, suffix: str, radius: str, height: str, parent=None):
        """A ``Part::Cylinder`` from its parent's origin along the parent's local z axis."""
        obj = self._add('Part::Cylinder', suffix, parent)
        obj.setExpression('Radius', self.expr(radius))
        obj.setExpression('Height', self.expr(height))
        return obj

    def frame(self, suffix: str, placement: str, parent=None):
        """A nested ``App::Part`` (a kinematic frame) with an expression-bound placement."""
        obj = self._add('App::Part', suffix, parent)
        obj.setExpression('Placement', self.expr(placement))
        return obj


def _placement(x: str, y: str, z: str, axis: str = 'z', angle: str = '0 deg') -> str:
    return (f'create(<<placement>>; create(<<vector>>; {x}; {y}; {z}); '
            f'create(<<rotation>>; create(<<vector>>; {_AXIS_VECTORS[axis]}); {angle}))')


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
              '{P}.height / 2 - {P}.top')
    _corner_posts(model, 'Leg', '{P}.leg', '{P}.height - {P}.top', '-{P}.height / 2')


def build_chair(model: ModelBuilder) -> None:
    """Chair: seat on four legs, backrest along the +y edge."""
    model.parameter('seat_height', '=height * 0.5', 'seat height')
    model.parameter('seat', '=height * 0.05', 'seat thickness')
    model.parameter('leg', '=min(length; width) * 0.08', 'leg side')
    model.parameter('back', '=width * 0.1', 'backrest thickness')
    model.box('Seat', '{P}.length', '{P}.width', '{P}.seat', '-{P}.length / 2', '-{P}.width / 2',
              '-{P}.height / 2 + {P}.seat_height - {P}.seat')
    _corner_posts(model, 'Leg', '{P}.leg', '{P}.seat_height - {P}.seat', '-{P}.height / 2')
    model.box('Backrest', '{P}.length', '{P}.back', '{P}.height - {P}.seat_height',
              '-{P}.length / 2', '{P}.width / 2 - {P}.back', '-{P}.height / 2 + {P}.seat_height')


def build_sofa(model: ModelBuilder) -> None:
    """Sofa: seat block between two armrests, backrest along the +y edge."""
    model.parameter('seat_height', '=height * 0.55', 'seat height')
    model.parameter('back', '=width * 0.25', 'backrest depth')
    model.parameter('arm', '=length * 0.1', 'armrest width')
    model.parameter('arm_height', '=height * 0.75', 'armrest height')
    model.box('Seat', '{P}.length - 2 * {P}.arm', '{P}.width - {P}.back', '{P}.seat_height',
              '-{P}.length / 2 + {P}.arm', '-{P}.width / 2', '-{P}.height / 2')
    model.box('Backrest', '{P}.length', '{P}.back', '{P}.height', '-{P}.length / 2',
              '{P}.width / 2 - {P}.back', '-{P}.height / 2')
    for suffix, x in (('ArmrestLeft', '-{P}.length / 2'), ('ArmrestRight',
                                                           '{P}.length / 2 - {P}.arm')):
        model.box(suffix, '{P}.arm', '{P}.width - {P}.back', '{P}.arm_height', x, '-{P}.width / 2',
                  '-{P}.height / 2')


def build_bookcase(model: ModelBuilder) -> None:
    """Bookcase: sides, top, bottom, back panel and three shelves."""
    model.parameter('board', '=min(length; width) * 0.06', 'board thickness')
    inner = '{P}.length - 2 * {P}.board'
    for suffix, x in (('SideLeft', '-{P}.length / 2'), ('SideRight',
                                                        '{P}.length / 2 - {P}.board')):
        model.box(suffix, '{P}.board', '{P}.width', '{P}.height', x, '-{P}.width / 2',
                  '-{P}.height / 2')
    for suffix, z in (('Bottom', '-{P}.height / 2'), ('Top', '{P}.height / 2 - {P}.board')):
        model.box(suffix, inner, '{P}.width', '{P}.board', '-{P}.length / 2 + {P}.board',
                  '-{P}.width / 2', z)
    model.box('Back', inner, '{P}.board', '{P}.height - 2 * {P}.board',
              '-{P}.length / 2 + {P}.board', '{P}.width / 2 - {P}.board',
              '-{P}.height / 2 + {P}.board')
    for shelf in (1, 2, 3):
        model.box(f'Shelf{shelf}', inner, '{P}.width - {P}.board', '{P}.board',
                  '-{P}.length / 2 + {P}.board', '-{P}.width / 2',
                  f'-{{P}}.height / 2 + {shelf} * {{P}}.height / 4 - {{P}}.board / 2')


def build_printer(model: ModelBuilder) -> None:
    """3D printer: base, four frame posts, top frame, print bed and print head."""
    model.parameter('base', '=height * 0.12', 'base height')
    model.parameter('top', '=height * 0.06', 'top frame thickness')
    model.parameter('post', '=min(length; width) * 0.06', 'frame post side')
    model.parameter('bed_height', '=height * 0.4', 'print bed height above the floor')
    model.parameter('head', '=min(length; width) * 0.2', 'print head size')
    model.box('Base', '{P}.length', '{P}.width', '{P}.base', '-{P}.length / 2', '-{P}.width / 2',
              '-{P}.height / 2')
    _corner_posts(model, 'Post', '{P}.post', '{P}.height - {P}.base - {P}.top',
                  '-{P}.height / 2 + {P}.base')
    model.box('TopFrame', '{P}.length', '{P}.width', '{P}.top', '-{P}.length / 2',
              '-{P}.width / 2', '{P}.height / 2 - {P}.top')
    model.box('Bed', '{P}.length * 0.7', '{P}.width * 0.7', '{P}.base * 0.3', '-{P}.length * 0.35',
              '-{P}.width * 0.35', '-{P}.height / 2 + {P}.bed_height')
    model.box('Head', '{P}.head', '{P}.head', '{P}.head', '-{P}.head / 2', '-{P}.head / 2',
              '{P}.height / 2 - {P}.top - {P}.head')


def build_yumi(model: ModelBuilder) -> None:
    """ABB YuMi: body, head and two 7-joint arms; ``right_joint_N``/``left_joint_N`` in degrees.

    The robot faces +y, so its right arm hangs at +x. With all joints at 0 both arms hang straight
    down beside the body. Each joint is a nested ``App::Part`` rotated by its angle cell.
    """
    model.parameter('shoulder_z', '=height * 0.3', 'shoulder height above the box centre')
    model.parameter('radius', '=min(length; width) * 0.05', 'arm link radius')
    model.parameter('shoulder_x', '=length / 2 - radius',
                    'shoulder distance from the centre plane')
    model.parameter('short', '=height * 0.04', 'short link length')
    model.parameter('upper', '=height * 0.14', 'upper/fore arm link length')
    model.parameter('lower', '=height * 0.1', 'wrist link length')
    for side in ('right', 'left'):
        for joint in range(1, YUMI_JOINTS + 1):
            model.parameter(f'{side}_joint_{joint}', '=0 deg', f'{side} arm joint {joint} angle')
    model.box('Body', '{P}.length * 0.45', '{P}.width', '{P}.height * 0.75', '-{P}.length * 0.225',
              '-{P}.width / 2', '-{P}.height / 2')
    model.box('Head', '{P}.length * 0.3', '{P}.width * 0.6', '{P}.height * 0.25',
              '-{P}.length * 0.15', '-{P}.width * 0.3', '{P}.height / 4')
    for side, sign in (('right', ''), ('left', '-')):
        title = side.capitalize()
        parent = model.frame(
            f'{title}Shoulder',
            _placement(f'{sign}{{P}}.shoulder_x', '0 mm', '{P}.shoulder_z', 'x', '180 deg'))
        offset = '0 mm'
        for joint in range(1, YUMI_JOINTS + 1):
            axis, link = YUMI_JOINT_AXES[joint - 1], YUMI_LINKS[joint - 1]
            parent = model.frame(
                f'{title}Joint{joint}',
                _placement('0 mm', '0 mm', offset, axis, f'{{P}}.{side}_joint_{joint}'), parent)
            model.cylinder(f'{title}Link{joint}', '{P}.radius', f'{{P}}.{link}', parent=parent)
            offset = f'{{P}}.{link}'
        model.box(f'{title}Gripper', '{P}.radius * 2', '{P}.radius * 2', '{P}.short',
                  '-{P}.radius', '-{P}.radius', offset, parent)


def build_box(model: ModelBuilder) -> None:
    """Placeholder for a class without a model: the detection box itself."""
    model.box('Box', '{P}.length', '{P}.width', '{P}.height', '-{P}.length / 2', '-{P}.width / 2',
              '-{P}.height / 2')


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
    link.LinkedObject = library_object
    model.container.addObject(link)
    scale = ['{P}.%s / {P}.step_%s' % (name, name) for name in ('length', 'width', 'height')]
    link.setExpression('ScaleVector', model.expr(f'create(<<vector>>; {"; ".join(scale)})'))
    for axis, factor in zip('xyz', scale):
        link.setExpression(f'.Placement.Base.{axis}',
                           model.expr(f'-{factor} * {{P}}.step_centre_{axis}'))


BUILDERS = {
    'table': build_table,
    'chair': build_chair,
    'sofa': build_sofa,
    'bookcase': build_bookcase,
    'yumi': build_yumi,
    'printer': build_printer,
}


def add_detection(doc, detection: dict, index: int, library_object=None):
    """Create one detection's parametric model; returns (container, model kind).

    ``library_object`` is the imported user STEP shape for the class, if any; otherwise the
    built-in model is used, or a plain box for classes without one.
    """
    class_name = detection['class']
    base_name, builder = BUILTIN_MODELS.get(class_name, ('Detection', None))
    if library_object is not None:
        kind = 'step'
    else:
        kind = 'builtin' if builder else 'box'
    container = doc.addObject('App::Part', base_name)
    container.Label = f'{class_name} {index}'
    for prop, type_name, doc_text in (('DetectedClass', 'App::PropertyString',
                                       'class predicted by the detector'),
                                      ('Score', 'App::PropertyFloat', 'detection confidence'),
                                      ('SourceScan', 'App::PropertyString',
                                       'scan the detection came from'),
                                      ('SourceModel', 'App::PropertyString',
                                       'detector that produced it'),
                                      ('CadModel', 'App::PropertyString',
                                       'builtin, step or box (no model for the class)')):
        container.addProperty(type_name, prop, 'Synthdet', doc_text)
    container.DetectedClass = class_name
    container.Score = detection['score']
    container.SourceScan = detection['scan']
    container.SourceModel = detection['model']
    container.CadModel = kind
    centre = App.Vector(*(1000.0 * value for value in detection['center']))
    yaw_degrees = detection['yaw'] * 180.0 / 3.141592653589793
    container.Placement = App.Placement(centre, App.Rotation(App.Vector(0, 0, 1), yaw_degrees))
    sheet = doc.addObject('Spreadsheet::Sheet', f'{container.Name}_Parameters')
    container.addObject(sheet)
    model = ModelBuilder(doc, container, sheet)
    for alias, value in zip(('length', 'width', 'height'), detection['size']):
        model.parameter(alias, f'={1000.0 * value:.3f} mm', alias)
    if kind == 'step':
        build_step(model, library_object)
    elif kind == 'builtin':
        BUILDERS[builder](model)
    else:
        build_box(model)
    return container, kind
