"""synthdet's FreeCAD side: schema checks, the CAD library and the document builder.

Everything runs inside FreeCAD's own Python. ``schema`` also runs in synthdet's Python and takes
the predictions and corners rules from the standard-library-only ``synthdet.contracts``; the
other modules import nothing from synthdet.
"""
