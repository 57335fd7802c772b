"""synthdet's FreeCAD side: schema checks, placement rules, the CAD library, the document
builder and its look, and the checked opening of a document a user hands over.

Everything runs inside FreeCAD's own Python. ``schema`` also runs in synthdet's Python and takes
the predictions and corners rules from the standard-library-only ``synthdet.contracts``;
``opening`` and ``labels`` take the document check from ``synthdet.fcstd_guard`` and ``macro``
its process helpers from ``synthdet.processes`` (both standard library only); ``arrangement``
uses only the standard library; the other modules import nothing from synthdet.
"""
