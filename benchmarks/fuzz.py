"""
The fuzz suite's long run: the same hypothesis tests with many more examples each.

Runs, with ``CVC_FUZZ_EXAMPLES`` = N (default 5000) and hypothesis's randomness on:
``test/test_fuzz.py`` (every node callback in process, damaged bags replayed in full),
the fuzzed layout structures and texts of ``test/test_hostile_layouts.py`` and the JSON
columns against the careful reader of ``test/test_layout_columns.py``. Prints pytest's
summary and what the inputs came to (taken and refused, per entry point).

    ./dev.sh run python benchmarks/fuzz.py [--examples N]
"""

import argparse
import os
from pathlib import Path
import subprocess
import sys
import time

ROOT = Path(__file__).resolve().parents[1]
TESTS = ['test/test_fuzz.py',
         'test/test_hostile_layouts.py::test_fuzzed_structures_give_a_layout_or_a_layout_error',
         'test/test_hostile_layouts.py::test_fuzzed_texts_give_a_layout_or_a_layout_error',
         'test/test_layout_columns.py::test_columns_and_the_careful_reader_agree_on_any_json']


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--examples', type=int, default=5000,
                        help='hypothesis examples per test (the suite runs 150-400)')
    args = parser.parse_args()
    env = dict(os.environ, CVC_FUZZ_EXAMPLES=str(args.examples))
    started = time.monotonic()
    run = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-s', '-p', 'no:cacheprovider',
                          '--hypothesis-show-statistics', *TESTS], cwd=ROOT, env=env,
                         capture_output=True, text=True)
    lines = run.stdout.splitlines()
    for line in lines:
        if "{('" in line:                  # test_fuzz's outcomes, after pytest's dots
            print('inputs taken and refused:', line[line.index("{('"):])
        elif 'passed' in line or 'failed' in line or line.startswith(('FAILED', 'E ')):
            print(line)
    print(f'{args.examples} examples per test, {time.monotonic() - started:.0f} s, '
          f'exit code {run.returncode}')
    return run.returncode


if __name__ == '__main__':
    sys.exit(main())
