"""``python -m configurator {corners,freecad,labels,screenshot} ...``: run a sub-command."""
import argparse
import importlib
import sys

from synthdet.outputs import names_as_given

# sub-command -> module exposing ``add_arguments(parser)`` and ``run(args) -> int``
COMMANDS = {
    'corners': 'configurator.corners_cli',
    'freecad': 'configurator.freecad_cli',
    'labels': 'configurator.labels_cli',
    'screenshot': 'configurator.freecad_screenshot',
}


def main(argv: list[str] | None = None) -> int:
    """Parse the sub-command and run it; returns the process exit code."""
    parser = argparse.ArgumentParser(prog='python -m configurator', description=__doc__)
    subparsers = parser.add_subparsers(dest='command', required=True)
    modules = {}
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(module_name)
        modules[name] = module
        module.add_arguments(subparsers.add_parser(name, help=module.__doc__.splitlines()[0]))
    args = parser.parse_args(argv)
    names_as_given()
    return modules[args.command].run(args)


if __name__ == '__main__':
    sys.exit(main())
