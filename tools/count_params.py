"""Print the parameter count of the model in an mmdet3d config, total and per module.

Usage: python tools/count_params.py CONFIG [--depth N] [--cfg-options key=value ...]
Exit codes: 0, or 2 with one line naming the file for a CONFIG that cannot be loaded.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from projects.synthdet.bootstrap import ConfigFileError, add_cfg_options, load_config, run_tool
from synthdet.cli import OneLineParser, int_in

if TYPE_CHECKING:
    from torch import nn


def count_parameters(module: nn.Module) -> int:
    """Number of scalar parameters of ``module`` (trainable or not)."""
    return sum(p.numel() for p in module.parameters())


def parameter_table(model: nn.Module, depth: int) -> list[tuple[str, int]]:
    """(module name, count) rows for sub-modules up to ``depth`` levels deep, then the total."""
    rows = []

    def visit(module: nn.Module, prefix: str, level: int) -> None:
        for name, child in module.named_children():
            count = count_parameters(child)
            if count == 0:
                continue
            rows.append((prefix + name, count))
            if level < depth:
                visit(child, f'{prefix}{name}.', level + 1)

    visit(model, '', 1)
    rows.append(('total', count_parameters(model)))
    return rows


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='mmdet3d config file with a `model` entry')
    parser.add_argument(
        '--depth', type=int_in(1, 100), default=2, help='module levels to list, 1 to 100')
    add_cfg_options(parser)
    args = parser.parse_args()  # bad options end here, before torch and mmdet3d are loaded
    from mmdet3d.registry import MODELS
    from mmdet3d.utils import register_all_modules
    register_all_modules(init_default_scope=True)
    cfg = load_config(args.config, args.cfg_options)
    model = MODELS.build(cfg.model)
    for name, count in parameter_table(model, args.depth):
        indent = '  ' * name.count('.') if name != 'total' else ''
        print(f'{indent}{name:<{40 - len(indent)}} {count:>12}')


if __name__ == '__main__':
    run_tool(main, 'count_params.py', bad_input=(ConfigFileError, ))
