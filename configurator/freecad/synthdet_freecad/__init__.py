"""synthdet's FreeCAD side: schema checks, the CAD library and the document builder.

Everything but ``schema`` runs inside FreeCAD's own Python and imports nothing from synthdet.
"""
