"""Code that runs inside FreeCAD (``ImportSynthdet.FCMacro`` and ``synthdet_freecad``)."""
