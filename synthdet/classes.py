"""Class lists, areas and the one class palette (standard library only).

Every name has one meaning across the project:

- ``S3DIS_CLASSES``: the 13 classes of the real S3DIS, in mmdet3d's order;
- ``SEMANTIC_CLASSES``: the converter's semantic mask ids, ``S3DIS_CLASSES`` then the synthetic
  classes;
- ``DETECTION_CLASSES``: the 7 classes the detector learns, in the dataset's label order
  (``bbox_label_3d`` indexes into it);
- ``S3DIS_DETECTION_CLASSES``: the detection classes of the real S3DIS (experiment 1);
- ``GENERATED_CLASSES``: the detection classes the generator places in its rooms;
- ``STRUCTURE_CLASSES``: the room structure and clutter, never detected;
- ``GENERATED_STRUCTURE_CLASSES``: the structure the generator builds.
"""

S3DIS_CLASSES = ('ceiling', 'floor', 'wall', 'beam', 'column', 'window', 'door', 'table', 'chair',
                 'sofa', 'bookcase', 'board', 'clutter')
SYNTHETIC_CLASSES = ('yumi', '3dprinter')
SEMANTIC_CLASSES = S3DIS_CLASSES + SYNTHETIC_CLASSES

DETECTION_CLASSES = ('table', 'chair', 'sofa', 'bookcase', 'board', 'yumi', '3dprinter')
S3DIS_DETECTION_CLASSES = ('table', 'chair', 'sofa', 'bookcase', 'board')
GENERATED_CLASSES = ('table', 'chair', 'sofa', 'yumi', '3dprinter')
STRUCTURE_CLASSES = ('ceiling', 'floor', 'wall', 'beam', 'column', 'window', 'door', 'clutter')
GENERATED_STRUCTURE_CLASSES = ('ceiling', 'floor', 'wall', 'door', 'window', 'clutter')

# Semantic id of each detection class, in DETECTION_CLASSES order: (7, 8, 9, 10, 11, 13, 14).
DETECTION_SEMANTIC_IDS = tuple(SEMANTIC_CLASSES.index(name) for name in DETECTION_CLASSES)

# The label of an ignored region in a training room's boxes (a region whose locations the
# detector's class loss leaves out unless a true box claims them; tools/adapt.py's unsure boxes).
# mmdet3d's -1 ("don't care") boxes are dropped when the annotations are read; these are kept.
IGNORED_REGION_LABEL = -2

# Annotation files of any other class (the real S3DIS has e.g. ``stairs``) become this class.
FALLBACK_CLASS = 'clutter'

REAL_AREAS = (1, 2, 3, 4, 5, 6)
SYNTHETIC_AREAS = (7, 8, 9)

# Colors (0-255) of every class in every drawing: structure in greys, detections in strong hues.
CLASS_COLORS = {
    'ceiling': (222, 222, 222),
    'floor': (196, 196, 196),
    'wall': (158, 158, 158),
    'beam': (140, 140, 120),
    'column': (120, 120, 140),
    'window': (120, 190, 235),
    'door': (176, 140, 104),
    'clutter': (112, 112, 112),
    'table': (31, 119, 180),
    'chair': (255, 127, 14),
    'sofa': (44, 160, 44),
    'bookcase': (140, 86, 75),
    'board': (227, 119, 194),
    'yumi': (214, 39, 40),
    '3dprinter': (148, 103, 189),
}
UNKNOWN_COLOR = (60, 60, 60)


def class_color(name: str) -> tuple[int, int, int]:
    """The palette color (0-255) of a class, ``UNKNOWN_COLOR`` for classes outside it."""
    return CLASS_COLORS.get(name, UNKNOWN_COLOR)
