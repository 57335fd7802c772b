"""JSON and YAML configs are data: the check that one makes mmengine import or run nothing.

mmengine reads a ``.py`` config by running it: it is Python code (run only configs you trust).
A JSON or YAML config is read as data only; ``check_data_config`` refuses one
(``ConfigFileError``, one line naming the file and the key) that would make mmengine import or
run code:

- ``_base_`` naming a ``.py`` config (run as Python) or a package's config (``pkg::path``);
  JSON and YAML bases are checked the same way;
- ``custom_imports`` (mmengine imports the modules it lists);
- a YAML tag other than the plain data ones (mmengine's YAML loader runs
  ``!!python/object/apply:os.system``);
- a class name (``type``, an optimizer wrapper's ``constructor``, ``runner_type``) that no
  registry holds: mmengine imports any other dotted name and calls what it finds
  (``subprocess.getoutput``); a ``default_scope`` or ``_scope_`` that is no registry's scope
  (mmengine imports ``<scope>.registry``).

The registries are filled first with mmdet's, mmdet3d's and the plugin's classes
(``PLUGIN_MODULES``, what the project's ``.py`` configs import), so a data config names the
same classes as those without importing anything itself.
"""
import importlib
import json
from pathlib import Path

BASE_KEY, IMPORTS_KEY = '_base_', 'custom_imports'
CLASS_KEYS = ('type', 'constructor', 'runner_type')  # values mmengine looks up in a registry
SCOPE_KEYS = ('default_scope', '_scope_')  # values mmengine imports ``<scope>.registry`` of
DATA_SUFFIXES = ('.json', '.yml', '.yaml')
# the modules configs/tr3d/tr3d.py's custom_imports lists: the plugin's registered classes
PLUGIN_MODULES = ('projects.synthdet.datasets.synthdet_s3dis', 'projects.synthdet.models',
                  'projects.synthdet.evaluation.indoor_metric')
REGISTRY_MODULES = ('mmdet.registry', 'mmdet3d.registry', *PLUGIN_MODULES)


class ConfigFileError(ValueError):
    """A CONFIG that cannot be loaded as an mmengine config; the message names the file."""


def is_data_config(path: str | Path) -> bool:
    """Whether mmengine reads ``path`` as data (JSON or YAML), not as Python code."""
    return Path(path).suffix.lower() in DATA_SUFFIXES


def check_data_config(path: str | Path) -> None:
    """Raise ``ConfigFileError`` if the JSON or YAML config at ``path`` (or one of its
    ``_base_`` configs) would make mmengine import or run code; registers the classes a data
    config may name (``registered_names``)."""
    names, scopes = registered_names()
    pending, seen = [Path(path)], set()
    while pending:
        config = pending.pop()
        if config.resolve() in seen or not config.is_file():  # mmengine reports a missing base
            continue
        seen.add(config.resolve())
        data = _read_data(config)
        if not isinstance(data, dict):
            continue  # mmengine refuses a config that is no mapping
        pending.extend(_bases(config, data.get(BASE_KEY, [])))
        _check_values(config, data, names, scopes)


def registered_names() -> tuple[frozenset[str], frozenset[str]]:
    """The class names a config may use (bare and ``<scope>.<name>``) and the registry scopes,
    once mmdet's, mmdet3d's and the plugin's modules (``REGISTRY_MODULES``) and every
    registry's own locations are imported."""
    from mmengine import registry as registries
    for module in REGISTRY_MODULES:
        importlib.import_module(module)
    pending = [value for value in vars(registries).values()
               if isinstance(value, registries.Registry)]
    names, scopes, seen = set(), set(), set()
    while pending:
        registry = pending.pop()
        if id(registry) in seen:
            continue
        seen.add(id(registry))
        try:
            registry.import_from_location()
        except ImportError:  # a location that does not exist (mmdet3d's inferencers)
            pass
        scopes.add(registry.scope)
        names.update(registry.module_dict)
        names.update(f'{registry.scope}.{name}' for name in registry.module_dict)
        pending.extend(registry.children.values())
    return frozenset(names), frozenset(scopes)


def _read_data(config: Path) -> object:
    """The config's data, read as data only: JSON, or YAML with the plain data tags only."""
    text = config.read_text(encoding='utf-8', errors='replace')
    if config.suffix.lower() == '.json':
        try:
            return json.loads(text)
        except json.JSONDecodeError as error:
            raise ConfigFileError(f'{config}:{error.lineno}: not a JSON config '
                                  f'({error.msg})') from None
    import yaml
    try:
        return yaml.load(text, Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))
    except yaml.constructor.ConstructorError as error:
        line = error.problem_mark.line + 1 if error.problem_mark else 1
        raise ConfigFileError(f'{config}:{line}: a YAML tag that builds Python objects '
                              f'({_tag(error)}): a YAML config is data only') from None
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        line = mark.line + 1 if mark else 1
        problem = getattr(error, 'problem', None) or type(error).__name__
        raise ConfigFileError(f'{config}:{line}: not a YAML config ({problem})') from None


def _tag(error: Exception) -> str:
    """The YAML tag a ``ConstructorError`` names, shortened (``!!python/...``)."""
    problem = str(getattr(error, 'problem', '') or '')
    tag = problem.split('tag ', 1)[-1].strip(" '")
    return tag.replace('tag:yaml.org,2002:', '!!')[:80]


def _bases(config: Path, bases: object) -> list[Path]:
    """The JSON and YAML configs ``_base_`` names (relative to ``config``'s folder, as mmengine
    reads them); refuses a ``.py`` or package config."""
    bases = bases if isinstance(bases, list) else [bases]
    paths = []
    for base in bases:
        shown = repr(base)[:80]
        if not isinstance(base, str):
            raise ConfigFileError(f'{config}: "{BASE_KEY}" holds {shown}: expected the path of '
                                  'a JSON or YAML config')
        if '::' in base or not is_data_config(base):
            raise ConfigFileError(
                f'{config}: "{BASE_KEY}" names {shown}, which mmengine runs or imports as '
                'Python: a JSON or YAML config is data only and may build on JSON or YAML '
                'configs only (.py configs are code: run only ones you trust)')
        paths.append(config.parent / base)
    return paths


def _check_values(config: Path, data: dict, names: frozenset[str],
                  scopes: frozenset[str]) -> None:
    """Refuse the first key of ``data`` (at any depth) that would import or run code."""
    pending, seen = [('', data)], set()
    while pending:
        where, value = pending.pop()
        if id(value) in seen:  # a YAML alias: checked once
            continue
        seen.add(id(value))
        items = value.items() if isinstance(value, dict) else enumerate(value)
        for key, item in items:
            path = f'{where}.{key}'.lstrip('.') if isinstance(value, dict) else f'{where}[{key}]'
            reason = _refusal(key, item, names, scopes) if isinstance(value, dict) else None
            if reason is not None:
                raise ConfigFileError(f'{config}: "{path}" {reason}: a JSON or YAML config is '
                                      'data only')
            if isinstance(item, (dict, list)):
                pending.append((path, item))


def _refusal(key: object, value: object, names: frozenset[str],
             scopes: frozenset[str]) -> str | None:
    """Why mmengine would import or run code for ``key: value``, or None."""
    if key == IMPORTS_KEY:
        return 'imports Python modules (the tools register synthdet\'s own classes themselves)'
    if key in CLASS_KEYS and isinstance(value, str) and value not in names:
        return (f'is {value[:80]!r}, which no registry holds: mmengine would import it as a '
                'module path and call it')
    if key in SCOPE_KEYS and value is not None and value not in scopes:
        return (f'is {str(value)[:80]!r}, which is no registry scope ({", ".join(sorted(scopes))})'
                ': mmengine would import it')
    return None
