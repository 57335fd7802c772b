"""The trained detector that ships with synthdet: its config, its weights file and its model
card (``projects/synthdet/weights/README.md``), and how the inference tools choose between it
and a model the user names. No ML imports: the tools parse their arguments with it first.

``tools/scan2cad.py``, ``tools/predict.py`` and ``tools/eval_scans.py`` use the shipped model
when no config and checkpoint are given, and say which model they used.
"""
import hashlib
import os
import re
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
WEIGHTS_DIR = Path(__file__).resolve().parent / 'weights'
SHIPPED_CONFIG = REPO_ROOT / 'configs' / 'tr3d' / 'exp2_cpu.py'
SHIPPED_WEIGHTS = WEIGHTS_DIR / 'tr3d_exp2_cpu.pth'
MODEL_CARD = WEIGHTS_DIR / 'README.md'
CONFIG_SUFFIXES = ('.py', '.json', '.yaml', '.yml')
SHA256_LINE = re.compile(r'^sha256: `([0-9a-f]{64})`$', re.MULTILINE)


class ShippedModelError(ValueError):
    """The shipped model's file is missing or is not the one its model card describes."""


def file_sha256(path: str | os.PathLike) -> str:
    """The hex SHA-256 of a file, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, 'rb') as stream:
        for block in iter(lambda: stream.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()


def card_sha256(card: Path = MODEL_CARD) -> str:
    """The SHA-256 the model card gives for the weights (its line ``sha256: `<64 hex>```)."""
    found = SHA256_LINE.findall(card.read_text(encoding='utf-8'))
    if len(found) != 1:
        raise ShippedModelError(f'{card}: expected one line "sha256: `<64 hex digits>`", '
                                f'found {len(found)}')
    return found[0]


def shipped_model() -> tuple[Path, Path]:
    """The shipped model's config and weights, the weights checked against the model card's
    SHA-256; :class:`ShippedModelError` naming the file when it is missing or differs."""
    if not SHIPPED_WEIGHTS.is_file():
        raise ShippedModelError(f'{SHIPPED_WEIGHTS}: the shipped model is missing; restore it '
                                'with git (git checkout -- projects/synthdet/weights) or name a '
                                'model with --config and --checkpoint')
    if file_sha256(SHIPPED_WEIGHTS) != card_sha256():
        raise ShippedModelError(f'{SHIPPED_WEIGHTS}: its SHA-256 differs from the one in '
                                f'{MODEL_CARD}; restore it with git or name a model with '
                                '--config and --checkpoint')
    return SHIPPED_CONFIG, SHIPPED_WEIGHTS


def split_model_arguments(arguments: list[str]) -> tuple[str | None, str | None, list[str]]:
    """``[CONFIG CHECKPOINT] INPUT...`` -> (config, checkpoint, inputs): the first two arguments
    are a model when the first one is a config file (``.py``, ``.json``, ``.yaml``, ``.yml``,
    suffixes no scan has); otherwise every argument is an input and the model is the shipped
    one (config and checkpoint None)."""
    if len(arguments) >= 2 and Path(arguments[0]).suffix.lower() in CONFIG_SUFFIXES:
        return arguments[0], arguments[1], arguments[2:]
    return None, None, list(arguments)


def resolve_model(config: str | None, checkpoint: str | None) -> tuple[str, str, str]:
    """(config, checkpoint, a line saying which model it is): the given pair, or the shipped
    model when both are None. ``ValueError`` when only one of them is given."""
    if (config is None) != (checkpoint is None):
        raise ValueError('give both --config and --checkpoint, or neither for the shipped model')
    if config is not None:
        return config, checkpoint, f'model: {config} with {checkpoint}'
    shipped_config, weights = shipped_model()
    relative = weights.relative_to(REPO_ROOT)
    return (str(shipped_config), str(weights),
            f'model: the shipped model {relative} ({SHIPPED_CONFIG.name}, model card '
            f'{MODEL_CARD.relative_to(REPO_ROOT)})')
