"""S3DIS text formatting speed: the writer's vectorised lookup-table formatter vs per-line Python
formatting and ``np.savetxt``, on the same 1M points (same bytes).

    .venv/bin/python benchmarks/bench_writer.py [--points 1000000] [--repeats 3]

Every method starts from the same numpy arrays (the per-line loop's conversion to Python tuples
is timed with it) and gets the best of ``--repeats`` runs, garbage collector off. Ends with
``text writer speedup vs the fastest alternative (<name>): <N>x``.
"""
import gc
import io
import time

import numpy as np

from generator.writer import format_lines
from synthdet.cli import OneLineParser


def best_of(fn, repeats: int) -> tuple[float, object]:
    """Best seconds of ``repeats`` runs, with the garbage collector off (the per-line loop makes
    a tuple per line, and collections would slow it down)."""
    times, result = [], None
    gc.collect()
    gc.disable()
    try:
        for _ in range(repeats):
            start = time.perf_counter()
            result = fn()
            times.append(time.perf_counter() - start)
    finally:
        gc.enable()
    return min(times), result


def main() -> None:
    parser = OneLineParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--points', type=int, default=1_000_000)
    parser.add_argument('--repeats', type=int, default=3, help='runs per method (best kept)')
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    # coordinates already on the millimetre grid, so every method prints the same digits
    # (+ 0.0 turns -0.0 into 0.0: Python prints '-0.000', the writer never does)
    xyz = np.rint(rng.uniform(-2.0, 12.0, (args.points, 3)) * 1000) / 1000 + 0.0
    rgb = rng.integers(0, 256, (args.points, 3))

    vector_s, (text, _) = best_of(lambda: format_lines(xyz, rgb), args.repeats)

    def per_line():
        rows = [(*a, *b) for a, b in zip(xyz.tolist(), rgb.tolist())]
        return ''.join('%.3f %.3f %.3f %d %d %d\n' % row for row in rows).encode()

    def savetxt():
        buffer = io.BytesIO()
        np.savetxt(buffer, np.concatenate([xyz, rgb], axis=1), fmt='%.3f %.3f %.3f %d %d %d')
        return buffer.getvalue()

    python_s, python_text = best_of(per_line, args.repeats)
    savetxt_s, savetxt_text = best_of(savetxt, args.repeats)
    assert text == python_text == savetxt_text, 'the three methods must print the same bytes'
    print(f'{args.points:,} lines, {len(text) / 1e6:.1f} MB, identical output from all methods')
    print(f'{"method":<38}{"seconds":>10}{"lines/s":>14}')
    alternatives = {'per-line Python % formatting': python_s, 'np.savetxt': savetxt_s}
    for name, seconds in (('vectorised lookup tables (writer)', vector_s), *alternatives.items()):
        print(f'{name:<38}{seconds:>10.2f}{args.points / seconds:>14,.0f}')
    fastest = min(alternatives, key=alternatives.get)
    print(f'text writer speedup vs the fastest alternative ({fastest}), best of {args.repeats}: '
          f'{alternatives[fastest] / vector_s:.1f}x')


if __name__ == '__main__':
    main()
