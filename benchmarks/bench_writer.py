"""S3DIS text formatting speed: the writer's vectorised lookup-table formatter vs per-line Python
formatting and ``np.savetxt``, on the same 1M points (same bytes).

    .venv/bin/python benchmarks/bench_writer.py [--points 1000000]

Ends with ``text writer speedup vs per-line Python formatting: <N>x``.
"""
import argparse
import io
import time

import numpy as np

from generator.writer import format_lines


def best_of(fn, repeats: int = 3) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--points', type=int, default=1_000_000)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    # coordinates already on the millimetre grid, so every method prints the same digits
    # (+ 0.0 turns -0.0 into 0.0: Python prints '-0.000', the writer never does)
    xyz = np.rint(rng.uniform(-2.0, 12.0, (args.points, 3)) * 1000) / 1000 + 0.0
    rgb = rng.integers(0, 256, (args.points, 3))

    vector_s, (text, _) = best_of(lambda: format_lines(xyz, rgb))
    rows = [(*a, *b) for a, b in zip(xyz.tolist(), rgb.tolist())]
    python_s, python_text = best_of(
        lambda: ''.join('%.3f %.3f %.3f %d %d %d\n' % row for row in rows).encode(), repeats=1)

    def savetxt():
        buffer = io.BytesIO()
        np.savetxt(buffer, np.concatenate([xyz, rgb], axis=1), fmt='%.3f %.3f %.3f %d %d %d')
        return buffer.getvalue()

    savetxt_s, savetxt_text = best_of(savetxt, repeats=1)
    assert text == python_text == savetxt_text, 'the three methods must print the same bytes'
    print(f'{args.points:,} lines, {len(text) / 1e6:.1f} MB, identical output from all methods')
    print(f'{"method":<38}{"seconds":>10}{"lines/s":>14}')
    for name, seconds in (('vectorised lookup tables (writer)', vector_s),
                          ('per-line Python % formatting', python_s), ('np.savetxt', savetxt_s)):
        print(f'{name:<38}{seconds:>10.2f}{args.points / seconds:>14,.0f}')
    print(f'text writer speedup vs per-line Python formatting: {python_s / vector_s:.1f}x')


if __name__ == '__main__':
    main()
