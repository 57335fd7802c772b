"""docs/benchmarks.md shows the end of each benchmark's output, without Python's warnings."""
import datetime
import json
import re
import tempfile
import time

from tools import collect_benchmarks


def test_page_shows_the_end_of_an_output_without_warnings(tmp_path):
    output = [f'[bench] step {i}: started (log work_dirs/x/logs/{i}.log)' for i in range(60)]
    output[3:3] = [
        'site-packages/m/__init__.py:221: UserWarning: compiled with CPU_ONLY', '  warnings.warn('
    ]
    output += [
        'x.py:9: DeprecationWarning: old', '  import old', 'table  0.9', 'summary: 3.0x faster'
    ]
    (tmp_path / 'demo.json').write_text(json.dumps(dict(
        name='demo', command='.venv/bin/python benchmarks/bench_demo.py', returncode=0,
        seconds=1.0, load_before=[0, 0, 0], load_after=[0, 0, 0],
        finished=time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime(86400 * 20_000)), last_line='summary: 3.0x faster')))
    (tmp_path / 'demo.txt').write_text('\n'.join(output) + '\n')
    page = collect_benchmarks.render([collect_benchmarks.kept_output('demo', tmp_path)], [],
                                     tmp_path)
    block = page.split('```')[1].strip().splitlines()
    assert len(block) == collect_benchmarks.SHOWN_LINES
    assert block[-2:] == ['table  0.9', 'summary: 3.0x faster']
    assert 'Warning' not in page and 'warnings.warn(' not in page and 'import old' not in page
    assert block[0] == '[bench] step 22: started (log work_dirs/x/logs/22.log)'
    assert 'The last 40 lines of the output' in page
    short = collect_benchmarks.shown_output(['a', 'b'])
    assert short == ['a', 'b']


def test_random_temporary_folder_names_are_scrubbed():
    temporary = tempfile.gettempdir()
    text = collect_benchmarks.scrub(f'output in {temporary}/tmpn37p8sz_/data and '
                                    f'{temporary}/synthdet-bench-hall-x/hall.laz')
    assert text == 'output in $TMPDIR/<random>/data and $TMPDIR/synthdet-bench-hall-x/hall.laz'


def test_the_page_dates_only_what_the_kept_records_date(tmp_path):
    """Every date on the page is a kept record's finishing time: the notes under the outputs
    carry none of their own, so a re-run cannot leave a stale date beside a new output."""
    finished = datetime.date(2031, 1, 2).isoformat() + ' 03:04 UTC'
    for name in collect_benchmarks.NOTES:
        (tmp_path / f'{name}.json').write_text(json.dumps(dict(
            name=name, command=f'.venv/bin/python benchmarks/bench_{name}.py', returncode=0,
            seconds=1.0, load_before=[0, 0, 0], load_after=[0, 0, 0], finished=finished,
            last_line='summary')))
        (tmp_path / f'{name}.txt').write_text('summary\n')
    records = [collect_benchmarks.kept_output(name, tmp_path) for name in collect_benchmarks.NOTES]
    page = collect_benchmarks.render(records, [], tmp_path)
    assert all(note in page for notes in collect_benchmarks.NOTES.values() for note in notes)
    dates = re.findall(r'\b\d{4}-\d{2}-\d{2}\b', page)
    assert dates == [finished.split()[0]] * 2 * len(collect_benchmarks.NOTES)
