"""Class lists and label ids shared by the converter, the dataset and the statistics."""

# Detection classes in METAINFO order: ``bbox_label_3d`` indexes into this tuple.
DETECTION_CLASSES = ('table', 'chair', 'sofa', 'bookcase', 'board', 'yumi', '3dprinter')

# Semantic mask ids: the 13 S3DIS classes in mmdet3d's order, then the synthetic classes.
SEMANTIC_CLASSES = ('ceiling', 'floor', 'wall', 'beam', 'column', 'window', 'door', 'table',
                    'chair', 'sofa', 'bookcase', 'board', 'clutter', 'yumi', '3dprinter')

# Semantic id of each detection class, in DETECTION_CLASSES order: (7, 8, 9, 10, 11, 13, 14).
DETECTION_SEMANTIC_IDS = tuple(SEMANTIC_CLASSES.index(name) for name in DETECTION_CLASSES)

# Annotation files of any other class (the real S3DIS has e.g. ``stairs``) become this class.
FALLBACK_CLASS = 'clutter'

REAL_AREAS = (1, 2, 3, 4, 5, 6)
SYNTHETIC_AREAS = (7, 8, 9)
