"""A work directory that holds one multi-step run: the settings it was made with, and the error
a failed step raises. The demo (``tools/demo.py``) and the benchmarks that run the pipeline's
tools step by step share them."""
import json
from pathlib import Path

from synthdet.outputs import write_text


class StepError(RuntimeError):
    """A pipeline step failed; the message names the step and its log file."""


def claim_work_dir(stamp: Path, wanted: dict) -> None:
    """Record a run's settings ``wanted`` in the work dir's ``stamp`` file; raise
    ``StepError`` if the stamp holds a run with other settings."""
    if stamp.is_file():
        found = json.loads(stamp.read_text())
        if found != wanted:
            raise StepError(f'{stamp}: this work dir holds a run with {found}, not {wanted}; '
                            'choose another --work-dir')
    else:
        stamp.parent.mkdir(parents=True, exist_ok=True)
        write_text(stamp, json.dumps(wanted) + '\n')
