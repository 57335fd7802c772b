# Runs inside the FreeCAD GUI (started by `python -m configurator screenshot`): open the
# document as a user would (checked first: synthdet_freecad.opening), save what the 3D view
# shows as a PNG, report and quit. Options come from SYNTHDET_SCREENSHOT (a JSON: document,
# out, width, height, result, and paths: the folders holding synthdet_freecad and synthdet).
import json
import os
import sys
import traceback

import FreeCADGui as Gui

options = json.load(open(os.environ['SYNTHDET_SCREENSHOT'], encoding='utf-8'))
result = {'status': 'error', 'error': None}
sys.path.extend(path for path in options['paths'] if path not in sys.path)  # FreeCAD's first
try:
    from synthdet_freecad.opening import open_document
    try:
        doc = open_document(options['document'])
    except (OSError, ValueError) as error:  # not an FCStd, or refused: one line
        raise RuntimeError(f'FreeCAD cannot open it: {str(error).strip()}') from None
    Gui.updateGui()
    view = Gui.getDocument(doc.Name).activeView()
    view.saveImage(options['out'], options['width'], options['height'], 'White')
    result.update(
        status='ok',
        visible=sum(1 for obj in doc.Objects if obj.ViewObject.Visibility),
        objects=len(doc.Objects))
except RuntimeError as error:
    result['error'] = str(error)
except Exception as error:  # the process boundary: every failure goes to the result file
    result['error'] = f'{type(error).__name__}: {error}\n{traceback.format_exc()}'
finally:
    try:  # a result that cannot be written (a full disk) still ends FreeCAD, not the timeout
        with open(options['result'], 'w', encoding='utf-8') as stream:
            json.dump(result, stream)
    finally:
        os._exit(0)  # quit without the GUI's shutdown (no window manager, no OpenGL teardown)
