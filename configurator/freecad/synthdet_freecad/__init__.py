"""synthdet's FreeCAD side: schema checks, placement rules, the CAD library, the document
builder and its look.

Everything runs inside FreeCAD's own Python. ``schema`` also runs in synthdet's Python and takes
the predictions and corners rules from the standard-library-only ``synthdet.contracts``;
``arrangement`` uses only the standard library; the other modules import nothing from synthdet.
"""
