"""The paper's Table 1: detection instances per class and area, counted from the info pickles."""
from collections import Counter
from pathlib import Path
from typing import Sequence

from synthdet.classes import REAL_AREAS
from synthdet.info_files import labelled_boxes

TABLE1_FORMAT = 'synthdet.table1/1'
TABLE1_CLASSES = ('chair', 'table', 'sofa', 'bookcase', 'board', 'yumi', '3dprinter')


def info_path(data_root: str | Path, area: int, prefix: str = 's3dis') -> Path:
    return Path(data_root) / f'{prefix}_infos_Area_{area}.pkl'


def find_info_areas(data_root: str | Path, prefix: str = 's3dis') -> list[int]:
    """Areas N with a ``<prefix>_infos_Area_N.pkl`` in data_root, sorted."""
    names = (
        p.name[len(f'{prefix}_infos_Area_'):-len('.pkl')]
        for p in Path(data_root).glob(f'{prefix}_infos_Area_*.pkl'))
    return sorted(int(n) for n in names if n.isdigit())


def count_instances(data_root: str | Path,
                    areas: Sequence[int] | None = None,
                    prefix: str = 's3dis') -> dict[int, Counter]:
    """Count detection instances per class name in each area's info pickle
    (``<prefix>_infos_Area_N.pkl``, the ``--extra-tag`` of ``tools/create_data.py``).

    Label ids are resolved through the pickle's own ``metainfo['categories']``; instances
    labelled -1 (ignored classes) are not counted.
    """
    areas = find_info_areas(data_root, prefix) if areas is None else list(areas)
    if not areas:
        raise FileNotFoundError(f'{data_root}: no {prefix}_infos_Area_N.pkl found')
    counts = {}
    for area in areas:
        path = info_path(data_root, area, prefix)
        if not path.is_file():
            raise FileNotFoundError(f'{path}: info pickle not found (run tools/create_data.py)')
        counts[area] = Counter(name for _, boxes in labelled_boxes(path)
                               for name, _ in boxes)
    return counts


def table1_rows(counts: dict[int, Counter],
                classes: Sequence[str] = TABLE1_CLASSES) -> list[tuple[str, list[float]]]:
    """Rows of Table 1: one per area, S3DIS total (areas 1-6), synthetic total (the other
    areas), total, and the synthetic share in % (NaN where a class has no instance)."""

    def total(areas):
        return [sum(counts[a][c] for a in areas) for c in classes]

    real = [a for a in counts if a in REAL_AREAS]
    synthetic = [a for a in counts if a not in REAL_AREAS]
    rows = [(f'Area {a}', total([a])) for a in sorted(counts)]
    real_total, synthetic_total, grand_total = total(real), total(synthetic), total(counts)
    share = [100.0 * s / t if t else float('nan') for s, t in zip(synthetic_total, grand_total)]
    return rows + [('S3DIS (areas 1-6)', real_total), ('Synthetic (areas 7+)', synthetic_total),
                   ('Total', grand_total), ('Synthetic share %', share)]


def table1(counts: dict[int, Counter], classes: Sequence[str] = TABLE1_CLASSES) -> dict:
    """Table 1 as a JSON-able document: its areas, classes and the rows of ``table1_rows``
    (the synthetic share is ``None`` where a class has no instance)."""
    rows = [{
        'label': label,
        'values': [None if value != value else value for value in values]
    } for label, values in table1_rows(counts, classes)]
    return {
        'format': TABLE1_FORMAT,
        'areas': sorted(counts),
        'classes': list(classes),
        'rows': rows
    }


def format_table1(table: dict) -> str:
    """Table 1 as aligned plain text; zero counts print as '-' like the paper."""

    def cell(value: float | None, is_share: bool) -> str:
        if is_share:
            return '-' if value is None else f'{value:.1f}'
        return str(int(value)) if value else '-'

    classes, rows = table['classes'], table['rows']
    width = max(len(row['label']) for row in rows)
    widths = [max(len(c), 6) for c in classes]
    lines = [' ' * width + ' ' + ' '.join(c.rjust(w) for c, w in zip(classes, widths))]
    for row in rows:
        is_share = row['label'].startswith('Synthetic share')
        lines.append(row['label'].ljust(width) + ' ' +
                     ' '.join(cell(v, is_share).rjust(w) for v, w in zip(row['values'], widths)))
    return '\n'.join(lines)
