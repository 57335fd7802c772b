"""Generator configuration: defaults, loading from JSON/YAML and validation.

Every number a user may change lives in :data:`DEFAULTS`. A user file (``--config FILE``) overrides
any subset of it; unknown keys, wrong types, numbers that are not finite, negative counts,
probabilities outside [0, 1], inverted ranges and ranges beyond :data:`MAX_RANGE_VALUE` are
rejected with an error that names the file and the key (values cut short), before any work starts.

Default probabilities reproduce the synthetic counts of the paper's Table 1 for 3 areas x 50
rooms (chair 364, table 252, sofa 86, yumi 200, 3dprinter 192), with the procedural asset library:

- 4 wall slots per room, each holding a table (p=0.44) or a sofa (p=0.14) or nothing; some are
  dropped when no free place is found: 600 slots -> ~252 tables, ~80-93 sofas.
- 4 chair positions on the inner boundary, each used with p=0.61: 600 positions -> ~365 chairs.
- 2 sides (local left/right) per table, each holding a yumi (p=0.41) or a 3D printer (p=0.365);
  items that fit on no table of the library are dropped: ~504 sides -> ~197 yumis, ~192 printers.

Counts are binomial: over 150 rooms the sofa count alone has a standard deviation of ~10 %.

A file may add ``room_kinds`` (:data:`ROOM_KINDS`, generator/room_kinds.py): the share of
offices, meeting rooms, living rooms, bedrooms and labs among the rooms. The defaults have none:
every room is a factory room.
"""
import copy
import json
import math
from pathlib import Path
from typing import Any

from synthdet.classes import GENERATED_CLASSES
from synthdet.cli import InputFileError, check_input_file


DEFAULTS: dict[str, Any] = {
    'room': {
        # probability of each floor shape; they must sum to 1
        'shapes': {
            'box': 0.8,
            'L': 0.15,
            'U': 0.05
        },
        'width': [6.0, 11.0],  # x extent of the bounding box, metres
        'depth': [5.0, 9.0],  # y extent of the bounding box, metres
        'height': [2.8, 4.0],
        'doors': [1, 2],  # inclusive range of door openings per room
        'windows': [0, 3],  # inclusive range of window openings per room
    },
    'probabilities': {
        'table': 0.44,  # per wall slot
        'sofa': 0.14,  # per wall slot (table and sofa share the slot: sum <= 1)
        'chair': 0.61,  # per chair position on the inner boundary
        'yumi': 0.41,  # per table side (yumi and 3dprinter share the side: sum <= 1)
        '3dprinter': 0.365,  # per table side
    },
    'layout': {
        'wall_slots': 4,  # tables + sofas together, at most 4 (paper)
        'chair_positions': 4,  # chair positions on the inner boundary (paper)
        'chair_margin': 1.7,  # distance of the inner boundary from the walls, metres
        'wall_gap': [0.02, 0.12],  # gap between a wall item's back and its wall
        'clearance': 0.05,  # minimum free distance between any two objects
        # probability that a table side left without a YuMi or printer gets a crate as big as
        # a printer (a hard negative on the printers' tables)
        'free_side_crate': 0.7,
        'clutter': [2, 8],  # inclusive range of clutter objects per room
        'clutter_size': [0.2, 0.8],  # sides of the plain boxes and cylinders
        # probability of each clutter kind (generator/clutter.py); they must sum to 1
        'clutter_kinds': {
            'box': 0.0,
            'cylinder': 0.04,
            'shelf': 0.14,
            'cabinet': 0.14,
            'machine': 0.1,
            'pallet': 0.1,
            'crate': 0.2,
            'cart': 0.08,
            'bin': 0.1,
            'pipe': 0.1
        },
    },
    'scanner': {
        'path_coverage': 0.8,  # the two crossing segments span 80 % of the room (paper)
        'sensor_height': 0.6667,  # fraction of the room height (paper: 2/3)
        'path_steps': 512,  # sensor positions along the path
        'aim_at_objects': True,  # object rays towards random points of object bounds
        'batch_rays': 262144,  # rays per Embree call
        'max_object_rays': 200,  # give up on object points after this many batches
        'range_noise': 0.0,  # std of the range error, metres (0 = paper-faithful)
        'angular_jitter': 0.0,  # std of the beam direction error, radians
        'dropout': 0.0,  # probability that a return is lost
        # the keys above belong to the paper sensor; the model is drawn per room (sum 1)
        'sensors': {
            'paper': 0.34,
            'tls': 0.33,
            'tablet': 0.33,
            'depth_frame': 0.0,
            'reconstruction': 0.0
        },
        # every sensor model: probability that a ray passes glass (printer doors, cabinet fronts)
        # to the surface behind it, as a laser crosses clear glass; 0: glass is opaque (paper)
        'glass_transmission': 0.9,
        'tls': {  # terrestrial laser scanner (generator/tls.py)
            'stations_per_cell': [1, 2],  # inclusive range of stations per grid cell / bay
            'height': [1.4, 1.7],  # tripod height, metres
            'wall_clearance': 0.5,  # station distance from its cell's sides, metres
            'object_clearance': 0.5,  # station distance from any object's bounds, metres
            'angular_step_deg': None,  # beam grid step; null: from the point budget
            'oversample': 8.0,  # the budget rule's beams per point of the budget
            'min_angular_step_deg': 0.1,  # the finest step the budget rule goes to
            # the export's point spacing: one return per cube of this side (metres) of the
            # stations' merged returns, before the budget's random subset; null: every return
            'point_spacing': 0.01,
            'min_elevation_deg': -60.0,  # the tripod hides the cone below
            'min_range': 0.6,
            'max_range': 60.0,
            'range_noise': [0.002, 0.0005],  # std a + b * d of the range error, metres
            'mixed_pixels': 0.5,  # share of the returns at depth edges that land in between
            'edge_jump': 0.1,  # depth step between neighbouring beams that makes an edge, metres
        },
        'tablet': {  # handheld / tablet LiDAR (generator/tablet.py)
            'poses': 512,  # device poses along the walk
            'height': [1.2, 1.6],  # hand height, metres
            'wall_distance': 1.0,  # walk this far from the cell's sides, metres
            'fov_deg': [60.0, 48.0],  # horizontal, vertical field of view
            'wall_look': 0.7,  # share of the walk facing the walls (the rest: inwards, ahead)
            'sway_deg': 50.0,  # the view swings this far left and right of its direction
            'pitch_deg': [-45.0, 15.0],  # and tilts through this range
            'min_range': 0.3,
            'max_range': 5.0,
            'range_noise': 0.01,  # std of the range error, metres
            'far_keep': 0.3,  # share of the returns kept at max_range (1 at min_range)
            'dark_luminance': 40.0,  # a triangle color darker than this (0-255) is dark
            'dark_dropout': 0.7,  # probability that a return on a dark triangle is lost
            'shiny_dropout': 0.5,  # the same on shiny (metal palette) triangles
        },
        'reconstruction': {  # a fused RGB-D reconstruction (generator/reconstruction.py)
            # the walk and the depth camera: the tablet's keys, with a depth camera's range
            'poses': 512,
            'height': [1.2, 1.6],
            'wall_distance': 1.0,
            'fov_deg': [60.0, 48.0],
            'wall_look': 0.7,
            'sway_deg': 50.0,
            # lower than the tablet's: a person scanning a room also looks down at the floor,
            # which at -45 keeps a hole under the walk
            'pitch_deg': [-60.0, 15.0],
            'min_range': 0.3,
            'max_range': 4.0,
            'range_noise': 0.005,  # std of the range error of the fused surface, metres
            'far_keep': 1.0,  # share of the returns kept at max_range (1 at min_range)
            'dark_luminance': 40.0,
            'dark_dropout': 0.3,  # lower than the tablet's: fusion fills some of the holes
            'shiny_dropout': 0.3,
            'oversample': 8.0,  # returns cast per point of the budget
            'surface_spacing': 0.01,  # the fused surface: one return per cube of this side
            'ceiling_keep': 0.0,  # probability that a point of the ceiling is kept
        },
        'depth_frame': {  # one RGB-D camera frame (Kinect-like; generator/depth_frame.py)
            'height': [1.0, 1.6],  # camera height, metres
            'wall_distance': [0.2, 0.8],  # camera distance from the nearest wall, metres
            'object_clearance': 0.3,  # camera distance from any object's bounds, metres
            'aim_at_objects': 0.7,  # probability of facing an object (else a cell's centre)
            'pitch_deg': [0.0, 30.0],  # downward tilt of the view
            # Kinect v1 / Xtion (about 58 x 45 degrees) to the wider cameras of SUN RGB-D
            'horizontal_fov_deg': [57.0, 70.0],
            'vertical_fov_deg': [43.0, 56.0],
            'min_range': 0.5,
            'max_range': [4.5, 5.0],  # drawn per frame; no return beyond it
            'depth_noise': [0.0012, 0.0019],  # std a + b * depth**2 of the range error, metres
            'edge_jump': 0.1,  # depth step between neighbouring pixels that makes an edge, metres
            'edge_dropout': 0.8,  # probability that a pixel at a depth edge has no return
            'dark_luminance': 40.0,  # a triangle color darker than this (0-255) is dark
            'dark_dropout': 0.5,  # probability that a return on a dark triangle is lost
            'shiny_dropout': 0.4,  # the same on shiny (metal palette) triangles
            'min_object_points': 100,  # an object with fewer returns loses them
        },
    },
    'appearance': {  # drawn per room (generator/appearance.py); all 0 = the paper's flat colors
        'shading': 0.5,  # probability that colors are shaded by the angle to a light
        'instance_variation': 0.1,  # std of the per-instance color factor
        'colorless': 0.1,  # probability that every color is 0 (a scanner without camera)
        'ambient': 0.5,  # color factor of faces turned away from the light
        'light_tilt': [0.0, 60.0],  # angle of the light from the vertical, degrees [min, max]
    },
}

# A factory hall instead of rooms, used when a configuration file has a ``hall`` section (any
# subset of these keys). Rooms' configurations, and hence their meta.json, do not carry it.
HALL_DEFAULTS: dict[str, Any] = {
    'width': [20.0, 60.0],  # x extent, metres
    'depth': [15.0, 30.0],  # y extent, metres
    'height': [3.0, 4.0],  # as the rooms, so a model trained on rooms sees the same structure
    'bay': [7.0, 10.0],  # side of a bay; each bay is furnished like a room and scanned by a cross
    'partitions': 0.3,  # probability that the boundary between two bays is a partition wall
    'passage': 2.0,  # width of the passage left open in each partition, metres
    'doors': [2, 4],  # inclusive range of doors in the outer walls
    'windows': [0, 6],  # inclusive range of windows in the outer walls
}

# Room kinds (generator/room_kinds.py): a configuration file's ``room_kinds`` maps each to its
# probability (missing kinds are 0, the sum is 1). Without it every room is a factory room and
# nothing is drawn, so the rooms of earlier versions come out unchanged.
ROOM_KINDS = ('factory', 'office', 'meeting', 'living', 'bedroom', 'lab')

# mappings a user file replaces as a whole, named by what they map (missing keys are 0)
_DISTRIBUTIONS = {'shapes': 'room shape', 'clutter_kinds': 'clutter kind', 'sensors': 'sensor model'}
_SUM_GROUPS = (('probabilities', ('table', 'sofa')), ('probabilities', ('yumi', '3dprinter')))


class ConfigError(ValueError):
    """A bad generator configuration; the message names the source and the key."""


MAX_CONFIG_BYTES = 1 << 20  # a configuration file is a few KB; a larger one is refused


def _read_text(path: Path) -> str:
    """The UTF-8 text of a configuration file of at most ``MAX_CONFIG_BYTES``; ``ConfigError``
    naming the file (and the line of a byte that is not UTF-8) otherwise."""
    try:
        check_input_file(path, 'configuration file')
    except InputFileError as error:
        raise ConfigError(str(error)) from None
    with open(path, 'rb') as stream:
        data = stream.read(MAX_CONFIG_BYTES + 1)
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(f'{path}: larger than {MAX_CONFIG_BYTES:,} bytes; a configuration '
                          'file holds a few settings')
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as error:
        line = data[:error.start].count(b'\n') + 1
        raise ConfigError(f'{path}:{line}: not UTF-8 text (byte 0x{data[error.start]:02x})') \
            from None


def _parse_yaml(text: str, path: Path) -> Any:
    """YAML without aliases: ``*name`` would let a kilobyte expand to gigabytes (each alias
    level repeats the ones below), so a file using one is refused naming its line."""
    import yaml

    class NoAliasLoader(yaml.SafeLoader):
        """``yaml.SafeLoader`` that refuses aliases before composing them."""

        def compose_node(self, parent: Any, index: Any) -> Any:
            if self.check_event(yaml.AliasEvent):
                mark = self.peek_event().start_mark
                raise ConfigError(f'{path}:{mark.line + 1}: YAML aliases (*name) are not '
                                  'accepted in a configuration; write the values out')
            return super().compose_node(parent, index)

    try:
        return yaml.load(text, Loader=NoAliasLoader)
    except yaml.YAMLError as error:  # its text names the line and column
        raise ConfigError(f'{path}: cannot parse configuration: '
                          f'{" ".join(str(error).split())[:300]}') from None
    except RecursionError:
        raise ConfigError(f'{path}: cannot parse configuration: nested too deeply') from None


def load_config(path: str | Path | None = None) -> dict[str, Any]:
    """Return the defaults overridden by the JSON or YAML file at ``path``, validated."""
    config = copy.deepcopy(DEFAULTS)
    source = '<defaults>'
    if path is not None:
        path = Path(path)
        source = str(path)
        text = _read_text(path)
        if path.suffix.lower() in ('.yaml', '.yml'):
            user = _parse_yaml(text, path)
        else:
            try:
                user = json.loads(text)
            except (ValueError, RecursionError) as err:  # the message names line and column
                raise ConfigError(f'{path}: cannot parse configuration: {err}') from None
        if user is None:
            user = {}
        if not isinstance(user, dict):
            raise ConfigError(f'{path}: top level must be a mapping, got {type(user).__name__}')
        hall = user.pop('hall', None)
        kinds = user.pop('room_kinds', None)
        _merge(config, user, DEFAULTS, source, '')
        if kinds is not None:
            config['room_kinds'] = _room_kinds(kinds, source)
        if hall is not None:
            if not isinstance(hall, dict):
                raise ConfigError(f'{source}: "hall" must be a mapping')
            config['hall'] = copy.deepcopy(HALL_DEFAULTS)
            _merge(config['hall'], hall, HALL_DEFAULTS, source, 'hall.')
    validate_config(config, source)
    return config


def _room_kinds(value: Any, source: str) -> dict[str, float]:
    """A user's ``room_kinds`` as a probability per kind of :data:`ROOM_KINDS`."""
    if not isinstance(value, dict):
        raise ConfigError(f'{source}: "room_kinds" must be a mapping of room kind -> probability')
    for name in value:
        if name not in ROOM_KINDS:
            raise ConfigError(f'{source}: unknown room kind "{name}" in "room_kinds" '
                              f'(known: {", ".join(ROOM_KINDS)})')
    return {kind: value.get(kind, 0.0) for kind in ROOM_KINDS}


def _merge(target: dict, user: dict, reference: dict, source: str, prefix: str) -> None:
    for key, value in user.items():
        where = f'{prefix}{key}'
        if key not in reference and prefix == 'probabilities.':
            raise ConfigError(f'{source}: unknown class "{key}" in "probabilities" '
                              f'(classes: {", ".join(GENERATED_CLASSES)})')
        if key not in reference:
            known = ', '.join(sorted(reference))
            raise ConfigError(f'{source}: unknown key "{where}" (known here: {known})')
        if isinstance(reference[key], dict) and key not in _DISTRIBUTIONS:
            if not isinstance(value, dict):
                raise ConfigError(f'{source}: "{where}" must be a mapping')
            _merge(target[key], value, reference[key], source, where + '.')
        elif key in _DISTRIBUTIONS:  # a whole distribution: what it leaves out has p = 0
            what = _DISTRIBUTIONS[key]
            if not isinstance(value, dict):
                raise ConfigError(f'{source}: "{where}" must be a mapping of {what} -> '
                                  f'probability')
            for name in value:
                if name not in reference[key]:
                    raise ConfigError(f'{source}: unknown {what} "{name}" in "{where}" '
                                      f'(known: {", ".join(reference[key])})')
            target[key] = {s: value.get(s, 0.0) for s in reference[key]}
        else:
            target[key] = value


MAX_RANGE_VALUE = 10_000  # the largest value of a [min, max] range: metres, degrees or counts


def _shown(value: object, limit: int = 32) -> str:
    """``repr(value)`` for a message, at most ``limit`` characters (a 300-digit number is cut)."""
    text = repr(value)
    return text if len(text) <= limit else f'{text[:limit - 3]}...'


def _number(config: dict, section: str, key: str, source: str) -> float:
    value = config[section][key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f'{source}: "{section}.{key}" must be a number, got {_shown(value)}')
    try:
        number = float(value)
    except OverflowError:  # an integer beyond the range of a float
        number = math.inf
    if not math.isfinite(number):
        raise ConfigError(f'{source}: "{section}.{key}" must be a finite number, got '
                          f'{_shown(value)}')
    return number


def _range(config: dict, section: str, key: str, source: str, integer: bool = False) -> None:
    value = config[section][key]
    kind = int if integer else (int, float)
    if (not isinstance(value, (list, tuple)) or len(value) != 2
            or any(isinstance(v, bool) or not isinstance(v, kind) for v in value)):
        what = 'integers' if integer else 'numbers'
        raise ConfigError(f'{source}: "{section}.{key}" must be a list of two {what} [min, max], '
                          f'got {_shown(value)}')
    low, high = value
    if low < 0:
        raise ConfigError(f'{source}: "{section}.{key}" must not be negative, got {_shown(value)}')
    if low > high:
        raise ConfigError(f'{source}: "{section}.{key}" has min > max: {_shown(value)}')
    if not (0 <= low and high <= MAX_RANGE_VALUE):  # NaN fails too
        raise ConfigError(f'{source}: "{section}.{key}" must lie in [0, {MAX_RANGE_VALUE:,}], '
                          f'got {_shown(value)}')


def _distribution(config: dict, section: str, key: str | None, source: str) -> None:
    """Check the distribution ``config[section][key]`` (``config[section]`` when ``key`` is
    None)."""
    probs = config[section] if key is None else config[section][key]
    where = section if key is None else f'{section}.{key}'
    for name, p in probs.items():
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0.0 <= p <= 1.0:
            raise ConfigError(f'{source}: "{where}.{name}" must be a probability in '
                              f'[0, 1], got {_shown(p)}')
    if abs(sum(probs.values()) - 1.0) > 1e-6:
        raise ConfigError(f'{source}: "{where}" probabilities sum to '
                          f'{sum(probs.values()):g}, not 1')


def validate_config(config: dict[str, Any], source: str = '<config>') -> None:
    """Raise :class:`ConfigError` when any value of ``config`` is out of its domain."""
    probs = config['probabilities']
    for cls in probs:
        if cls not in GENERATED_CLASSES:
            raise ConfigError(f'{source}: unknown class "{cls}" in "probabilities" '
                              f'(classes: {", ".join(GENERATED_CLASSES)})')
        p = _number(config, 'probabilities', cls, source)
        if not 0.0 <= p <= 1.0:
            raise ConfigError(
                f'{source}: probability "probabilities.{cls}" = {p} is outside [0, 1]')
    for section, keys in _SUM_GROUPS:
        total = sum(float(config[section][k]) for k in keys)
        if total > 1.0 + 1e-9:
            raise ConfigError(
                f'{source}: "{section}.{keys[0]}" + "{section}.{keys[1]}" = {total:g} '
                f'> 1; they share one slot')
    _distribution(config, 'room', 'shapes', source)
    for key in ('width', 'depth', 'height'):
        _range(config, 'room', key, source)
        if config['room'][key][0] <= 0:
            raise ConfigError(f'{source}: "room.{key}" must be positive')
    if config['room']['width'][0] < 4.0 or config['room']['depth'][0] < 4.0:
        raise ConfigError(f'{source}: "room.width" and "room.depth" must be at least 4 m')
    if config['room']['height'][0] < 2.2:
        raise ConfigError(f'{source}: "room.height" must be at least 2.2 m')
    for key in ('doors', 'windows'):
        _range(config, 'room', key, source, integer=True)
    layout = config['layout']
    for key in ('wall_slots', 'chair_positions'):
        value = layout[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ConfigError(f'{source}: "layout.{key}" must be a non-negative integer, '
                              f'got {_shown(value)}')
    if layout['wall_slots'] > 4:
        raise ConfigError(f'{source}: "layout.wall_slots" = {layout["wall_slots"]}: tables and '
                          f'sofas share at most 4 wall slots')
    for key in ('chair_margin', 'clearance'):
        if _number(config, 'layout', key, source) < 0:
            raise ConfigError(f'{source}: "layout.{key}" must not be negative')
    if not 0.0 <= _number(config, 'layout', 'free_side_crate', source) <= 1.0:
        raise ConfigError(f'{source}: "layout.free_side_crate" = '
                          f'{layout["free_side_crate"]} is outside [0, 1]')
    _range(config, 'layout', 'wall_gap', source)
    _range(config, 'layout', 'clutter', source, integer=True)
    _range(config, 'layout', 'clutter_size', source)
    _distribution(config, 'layout', 'clutter_kinds', source)
    scanner = config['scanner']
    for key in ('path_coverage', 'sensor_height', 'dropout'):
        value = _number(config, 'scanner', key, source)
        if not 0.0 <= value <= 1.0:
            raise ConfigError(f'{source}: "scanner.{key}" = {value} is outside [0, 1]')
    transmission = _number(config, 'scanner', 'glass_transmission', source)
    if not 0.0 <= transmission <= 1.0:
        raise ConfigError(
            f'{source}: "scanner.glass_transmission" = {transmission} is outside [0, 1]')
    if scanner['dropout'] >= 1.0:
        raise ConfigError(f'{source}: "scanner.dropout" must be below 1')
    if not isinstance(scanner['aim_at_objects'], bool):
        raise ConfigError(f'{source}: "scanner.aim_at_objects" must be true or false')
    for key in ('range_noise', 'angular_jitter'):
        if _number(config, 'scanner', key, source) < 0:
            raise ConfigError(f'{source}: "scanner.{key}" must not be negative')
    _validate_appearance(config, source)
    _validate_sensors(scanner, source)
    if 'hall' in config:
        _validate_hall(config, source)
    if 'room_kinds' in config:
        if 'hall' in config:
            raise ConfigError(f'{source}: "room_kinds" applies to rooms; the bays of a hall are '
                              f'furnished as factory rooms')
        _distribution(config, 'room_kinds', None, source)
    for key in ('path_steps', 'batch_rays', 'max_object_rays'):
        value = scanner[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(f'{source}: "scanner.{key}" must be a positive integer, '
                              f'got {_shown(value)}')


def _validate_appearance(config: dict[str, Any], source: str) -> None:
    for key in ('shading', 'colorless', 'ambient'):
        value = _number(config, 'appearance', key, source)
        if not 0.0 <= value <= 1.0:
            raise ConfigError(f'{source}: "appearance.{key}" = {value} is outside [0, 1]')
    if _number(config, 'appearance', 'instance_variation', source) < 0:
        raise ConfigError(f'{source}: "appearance.instance_variation" must not be negative')
    _range(config, 'appearance', 'light_tilt', source)
    if config['appearance']['light_tilt'][1] > 90:
        raise ConfigError(f'{source}: "appearance.light_tilt" must stay within [0, 90] degrees')


def _validate_sensors(scanner: dict[str, Any], source: str) -> None:
    """The sensor mix and the TLS, tablet, reconstruction and depth frame parameters."""
    _distribution({'scanner': scanner}, 'scanner', 'sensors', source)
    for sensor, ranges, probabilities, lengths in (
        ('tls', ('height', 'stations_per_cell'), ('mixed_pixels', ),
         ('wall_clearance', 'object_clearance', 'min_range', 'max_range', 'edge_jump')),
        ('tablet', ('height', ), ('wall_look', 'far_keep', 'dark_dropout', 'shiny_dropout'),
         ('wall_distance', 'min_range', 'max_range', 'range_noise', 'sway_deg', 'dark_luminance')),
        ('reconstruction', ('height', ),
         ('wall_look', 'far_keep', 'dark_dropout', 'shiny_dropout', 'ceiling_keep'),
         ('wall_distance', 'min_range', 'max_range', 'range_noise', 'sway_deg', 'dark_luminance')),
        ('depth_frame', ('height', 'wall_distance', 'pitch_deg', 'horizontal_fov_deg',
                         'vertical_fov_deg', 'max_range'),
         ('aim_at_objects', 'edge_dropout', 'dark_dropout', 'shiny_dropout'),
         ('object_clearance', 'min_range', 'edge_jump', 'dark_luminance')),
    ):
        where = f'scanner.{sensor}'
        view = {where: scanner[sensor]}  # _number and _range name the key by its full path
        for key in ranges:
            _range(view, where, key, source, integer=key == 'stations_per_cell')
        for key in probabilities:
            if not 0.0 <= _number(view, where, key, source) <= 1.0:
                raise ConfigError(f'{source}: "{where}.{key}" is outside [0, 1]')
        for key in lengths:
            if _number(view, where, key, source) < 0:
                raise ConfigError(f'{source}: "{where}.{key}" must not be negative')
        nearest_far = scanner[sensor]['max_range']  # a number, or the depth frame's drawn range
        if isinstance(nearest_far, (list, tuple)):
            nearest_far = nearest_far[0]
        if scanner[sensor]['min_range'] >= nearest_far:
            raise ConfigError(f'{source}: "{where}.min_range" must be below "{where}.max_range"')
    tls = scanner['tls']
    if tls['stations_per_cell'][0] < 1:
        raise ConfigError(f'{source}: "scanner.tls.stations_per_cell" must be at least 1')
    for key, largest in (('angular_step_deg', 10.0), ('point_spacing', 1.0)):
        value = tls[key]
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                  or not 0.0 < value <= largest):
            raise ConfigError(f'{source}: "scanner.tls.{key}" must be null or a number in '
                              f'(0, {largest:g}], got {_shown(value)}')
    if _number({'scanner.tls': tls}, 'scanner.tls', 'oversample', source) < 1.0:
        raise ConfigError(f'{source}: "scanner.tls.oversample" must be at least 1')
    finest = _number({'scanner.tls': tls}, 'scanner.tls', 'min_angular_step_deg', source)
    if not 0.0 < finest <= 10.0:
        raise ConfigError(f'{source}: "scanner.tls.min_angular_step_deg" must be in (0, 10], '
                          f'got {_shown(finest)}')
    elevation = _number({'scanner.tls': tls}, 'scanner.tls', 'min_elevation_deg', source)
    if not -90.0 <= elevation < 90.0:
        raise ConfigError(f'{source}: "scanner.tls.min_elevation_deg" must be in [-90, 90)')
    noise = tls['range_noise']
    if (not isinstance(noise, (list, tuple)) or len(noise) != 2
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) or v < 0
                   for v in noise)):
        raise ConfigError(f'{source}: "scanner.tls.range_noise" must be [a, b], two non-negative '
                          f'numbers (std a + b * distance), got {_shown(noise)}')
    for walker in ('tablet', 'reconstruction'):  # the reconstruction walks as the tablet does
        _validate_walk(scanner[walker], f'scanner.{walker}', source)
    reconstruction = {'scanner.reconstruction': scanner['reconstruction']}
    if _number(reconstruction, 'scanner.reconstruction', 'oversample', source) < 1.0:
        raise ConfigError(f'{source}: "scanner.reconstruction.oversample" must be at least 1')
    spacing = _number(reconstruction, 'scanner.reconstruction', 'surface_spacing', source)
    if not 0.0 < spacing <= 1.0:
        raise ConfigError(f'{source}: "scanner.reconstruction.surface_spacing" must be in (0, 1] '
                          f'metres, got {_shown(spacing)}')
    _validate_depth_frame(scanner['depth_frame'], source)


def _validate_walk(walker: dict[str, Any], where: str, source: str) -> None:
    """The field of view, pitch and poses of the tablet's walk (``where``: the section)."""
    for key, low, high in (('fov_deg', 1.0, 170.0), ('pitch_deg', -90.0, 90.0)):
        value = walker[key]
        if (not isinstance(value, (list, tuple)) or len(value) != 2
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)
                or not all(low <= v <= high for v in value)):
            raise ConfigError(f'{source}: "{where}.{key}" must be two numbers in '
                              f'[{low:g}, {high:g}] degrees, got {_shown(value)}')
    if walker['pitch_deg'][0] > walker['pitch_deg'][1]:
        raise ConfigError(f'{source}: "{where}.pitch_deg" has min > max')
    poses = walker['poses']
    if isinstance(poses, bool) or not isinstance(poses, int) or poses < 2:
        raise ConfigError(f'{source}: "{where}.poses" must be an integer >= 2, '
                          f'got {_shown(poses)}')


def _validate_depth_frame(frame: dict[str, Any], source: str) -> None:
    """The depth frame's parameters beyond the ranges, probabilities and lengths of
    :func:`_validate_sensors`."""
    where = 'scanner.depth_frame'
    if frame['pitch_deg'][1] > 90:
        raise ConfigError(f'{source}: "{where}.pitch_deg" must stay within [0, 90] degrees')
    for key in ('horizontal_fov_deg', 'vertical_fov_deg'):
        if not (1.0 <= frame[key][0] and frame[key][1] <= 170.0):
            raise ConfigError(f'{source}: "{where}.{key}" must lie in [1, 170] degrees, '
                              f'got {_shown(frame[key])}')
    noise = frame['depth_noise']
    if (not isinstance(noise, (list, tuple)) or len(noise) != 2
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0
                   or not math.isfinite(v) for v in noise)):
        raise ConfigError(f'{source}: "{where}.depth_noise" must be [a, b], two non-negative '
                          f'numbers (std a + b * depth**2), got {_shown(noise)}')
    least = frame['min_object_points']
    if isinstance(least, bool) or not isinstance(least, int) or least < 0:
        raise ConfigError(f'{source}: "{where}.min_object_points" must be a non-negative '
                          f'integer, got {_shown(least)}')


def _validate_hall(config: dict[str, Any], source: str) -> None:
    for key in ('width', 'depth', 'height', 'bay'):
        _range(config, 'hall', key, source)
    for key in ('doors', 'windows'):
        _range(config, 'hall', key, source, integer=True)
    hall = config['hall']
    if hall['bay'][0] < 4.0:
        raise ConfigError(f'{source}: "hall.bay" must be at least 4 m')
    if hall['width'][0] < hall['bay'][0] or hall['depth'][0] < hall['bay'][0]:
        raise ConfigError(f'{source}: "hall.width" and "hall.depth" must be at least "hall.bay"')
    if hall['height'][0] < 2.2:
        raise ConfigError(f'{source}: "hall.height" must be at least 2.2 m')
    partitions = _number(config, 'hall', 'partitions', source)
    if not 0.0 <= partitions <= 1.0:
        raise ConfigError(f'{source}: "hall.partitions" = {partitions} is outside [0, 1]')
    passage = _number(config, 'hall', 'passage', source)
    if not 0.8 <= passage < hall['bay'][0] - 1.0:
        raise ConfigError(f'{source}: "hall.passage" = {passage} must be at least 0.8 m and '
                          f'leave 1 m of wall in the smallest bay')
