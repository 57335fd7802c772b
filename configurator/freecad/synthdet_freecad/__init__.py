"""synthdet's FreeCAD side: schema checks, placement rules, the CAD library, the document
builder and its look.

``schema`` and ``arrangement`` use only the standard library and also run in synthdet's Python;
the rest runs inside FreeCAD's own Python. None imports anything from synthdet.
"""
