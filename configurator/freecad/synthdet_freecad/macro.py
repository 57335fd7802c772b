"""What ``ImportSynthdet.FCMacro`` runs: ask for the files (GUI) or read them from the
environment (headless), import, and report.

Headless options come from ``SYNTHDET_JOB`` (a ``synthdet.freecad-job/1`` JSON, written by
``python -m configurator freecad``) or from ``SYNTHDET_PREDICTIONS``, ``SYNTHDET_CORNERS``,
``SYNTHDET_OUT``, ``SYNTHDET_LIBRARY``, ``SYNTHDET_MIN_SCORE`` and ``SYNTHDET_WALL_THICKNESS``.
If ``SYNTHDET_RESULT`` is set, a ``synthdet.freecad-result/1`` JSON is written there, on
failure too; a headless failure also exits with code 1.
"""
import contextlib
import json
import os
import secrets
import traceback
import zipfile

import FreeCAD as App
# standard library only, importable wherever schema's synthdet.contracts is
from synthdet.processes import process_alive

from . import appearance, archive, document, labels, schema

ENV_JOB = 'SYNTHDET_JOB'
ENV_RESULT = 'SYNTHDET_RESULT'
ENV_OPTIONS = {
    'predictions': 'SYNTHDET_PREDICTIONS',
    'corners': 'SYNTHDET_CORNERS',
    'out': 'SYNTHDET_OUT',
    'library': 'SYNTHDET_LIBRARY',
    'min_score': 'SYNTHDET_MIN_SCORE',
    'wall_thickness': 'SYNTHDET_WALL_THICKNESS',
}
EXPECTED_ERRORS = (schema.SchemaError, ValueError, RuntimeError, OSError)


def options_from_environment(overrides: dict | None = None, require_out: bool = True) -> dict:
    """The import options: the job file named by ``SYNTHDET_JOB``, else the single variables
    (with ``overrides``, e.g. the files picked in the GUI, taking precedence)."""
    job_path = os.environ.get(ENV_JOB)
    if job_path and not overrides:
        return schema.read_job(job_path)
    raw = {'format': schema.JOB_FORMAT}
    for key, variable in ENV_OPTIONS.items():
        value = os.environ.get(variable)
        if not value:
            continue
        if key in ('min_score', 'wall_thickness'):
            try:
                value = float(value)
            except ValueError:
                raise schema.SchemaError(f'{variable}: expected a number, got {value!r}') from None
        raw[key] = value
    raw.update(overrides or {})
    if 'predictions' not in raw:
        raise schema.SchemaError(f'set {ENV_OPTIONS["predictions"]} (or {ENV_JOB})')
    if 'out' not in raw:
        if require_out:
            raise schema.SchemaError(f'set {ENV_OPTIONS["out"]} (or {ENV_JOB})')
        raw['out'] = '-'
    return schema.validate_job(raw, 'environment')


def import_into(doc, options: dict, look) -> dict:
    """Validate the option's files and import them into ``doc`` (colors into ``look``, an
    ``appearance.Look``); returns the import report."""
    predictions = schema.read_predictions(options['predictions'])
    corners = schema.read_corners(options['corners']) if options['corners'] else None
    return document.import_detections(doc, predictions, corners, options['library'],
                                      options['min_score'], options['wall_thickness'], look)


def write_result(path: str | None, result: dict) -> None:
    """Write the result JSON (atomically) if a result path was given."""
    if not path:
        return
    result = dict(result, format=schema.RESULT_FORMAT)
    temporary = f'{path}.tmp{os.getpid()}'
    with open(temporary, 'w', encoding='utf-8') as stream:
        json.dump(result, stream, indent=1, ensure_ascii=False)
    os.replace(temporary, path)


PARTIAL_MARK = '.partial-'  # .<name>.partial-<pid>-<random>.FCStd: a run's temporary file


def partial_path(out: str) -> str:
    """A temporary file next to ``out`` that no other run uses: this process's id and a
    random part in the name (FreeCAD wants the ``.FCStd`` suffix)."""
    folder, name = os.path.split(out)
    stem = name[:-len('.FCStd')]
    return os.path.join(folder, f'.{stem}{PARTIAL_MARK}{os.getpid()}-{secrets.token_hex(4)}.FCStd')


def remove_stale_partials(out: str) -> None:
    """Remove the temporary files (and FreeCAD backups of them, ``*.FCStd1``) that runs which
    are no longer alive left next to ``out``. Files of live runs stay."""
    folder, name = os.path.split(out)
    prefix = f'.{name[:-len(".FCStd")]}{PARTIAL_MARK}'
    try:
        entries = os.listdir(folder or '.')
    except OSError:
        return
    for entry in entries:
        pid = entry[len(prefix):].split('-', 1)[0]
        if entry.startswith(prefix) and pid.isdigit() and not process_alive(int(pid)):
            with contextlib.suppress(OSError):  # removed by another run meanwhile
                os.remove(os.path.join(folder, entry))


def save_atomically(doc, out: str, look) -> None:
    """Save ``doc`` (with the GUI view ``look`` writes) to a temporary file next to ``out``
    and rename it into place.

    The temporary name is this run's own, so runs writing the same ``out`` at once never touch
    each other's files (the last rename wins, each file complete). A failing save (also one
    FreeCAD only reports on its console, such as a full disk, found by reading the archive
    back) leaves the previous ``out`` untouched; temporary files of runs that died (killed)
    are removed first, and no FreeCAD backup (``*.FCStd1``) of a temporary file is left.
    The parts' shapes are stored by ``archive.save_copy``, in time linear in the parts.
    """
    remove_stale_partials(out)
    partial = partial_path(out)
    try:
        # the parts' shapes stored in linear time; FreeCAD reports some write errors only on
        # its console, so its archive is checked first
        archive.save_copy(doc, partial,
                          check=lambda path: _check_complete(path, read_members=False))
        look.write_gui_document(partial, doc)
        _check_complete(partial)
        os.replace(partial, out)
    finally:
        for leftover in (partial, partial + '1'):  # FreeCAD names its backup <file>1
            if os.path.isfile(leftover):
                os.remove(leftover)


def _check_complete(path: str, read_members: bool = True) -> None:
    """Raise ``OSError`` unless ``path`` is a whole FCStd archive: its directory lists
    ``Document.xml`` and, with ``read_members``, every member reads back intact."""
    try:
        with zipfile.ZipFile(path) as stored:
            complete = 'Document.xml' in stored.namelist() and \
                (not read_members or stored.testzip() is None)
    except (OSError, zipfile.BadZipFile):
        complete = False
    if not complete:
        raise archive.incomplete(path)


def run_headless() -> None:
    """Import from the environment's files into a new document and save it."""
    result_path = os.environ.get(ENV_RESULT)
    try:
        options = options_from_environment()
        out = os.path.abspath(options['out'])
        if not out.lower().endswith('.fcstd'):
            raise ValueError(f'output {out!r} must end with .FCStd')
        doc = App.newDocument('SynthdetRoom')
        doc.Label = os.path.splitext(os.path.basename(out))[0]
        look = appearance.Look()
        report = import_into(doc, options, look)
        try:
            os.makedirs(os.path.dirname(out), exist_ok=True)
        except OSError as error:
            raise OSError(f'cannot create the output folder {os.path.dirname(out)!r}: '
                          f'{error.strerror}') from None
        save_atomically(doc, out, look)
        App.closeDocument(doc.Name)
    except Exception as error:  # the process boundary: every failure goes to the result file
        if isinstance(error, EXPECTED_ERRORS):
            message = str(error)
        else:
            message = f'{type(error).__name__}: {error}\n{traceback.format_exc()}'
        App.Console.PrintError(f'synthdet import failed: {message}\n')
        write_result(result_path, {'status': 'error', 'error': message, 'warnings': []})
        raise SystemExit(1) from None
    for warning in report['warnings']:
        App.Console.PrintWarning(f'synthdet import: {warning}\n')
    write_result(result_path, dict(report, status='ok', error=None, document=out))


def run_gui() -> None:
    """Ask for the predictions (and optionally corners) and import into the active document."""
    import FreeCADGui as Gui
    from PySide import QtGui

    window = Gui.getMainWindow()
    predictions, _ = QtGui.QFileDialog.getOpenFileName(window, 'synthdet: predictions JSON', '',
                                                       'Predictions (*.json);;All files (*)')
    if not predictions:
        return
    corners, _ = QtGui.QFileDialog.getOpenFileName(
        window, 'synthdet: room corners JSON (cancel for no room)', os.path.dirname(predictions),
        'Corners (*.json);;All files (*)')
    try:
        options = options_from_environment({
            'predictions': predictions,
            'corners': corners or None
        },
                                           require_out=False)
        doc = App.ActiveDocument or App.newDocument('SynthdetRoom')
        look = appearance.Look()
        report = import_into(doc, options, look)
    except EXPECTED_ERRORS as error:
        QtGui.QMessageBox.critical(window, 'synthdet import', str(error))
        return
    if report['warnings']:
        QtGui.QMessageBox.warning(window, 'synthdet import', '\n'.join(report['warnings']))
    look.apply_in_gui(doc)


def main() -> None:
    """Run the import the way the current FreeCAD (GUI or headless) allows; headless with
    ``SYNTHDET_READ`` set, read a document's labels instead (``labels.run_headless``); in the
    GUI on a synthdet document, offer its corrections first (``edit_dialog``)."""
    if os.environ.get(labels.ENV_READ) and not App.GuiUp:
        labels.run_headless()
    elif App.GuiUp:
        from . import edit_dialog
        doc = App.ActiveDocument
        if doc is not None and edit_dialog.is_synthdet_document(doc):
            edit_dialog.run(doc, run_gui)
        else:
            run_gui()
    else:
        run_headless()
