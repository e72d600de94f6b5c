"""How long the hypothesis fuzzing runs: its examples per test."""

import os


def fuzz_examples(default):
    """
    Return the examples per fuzz test: ``CVC_FUZZ_EXAMPLES`` if set, else ``default``.

    The suite's defaults keep CI within minutes; ``benchmarks/fuzz.py`` sets more.
    """
    return int(os.environ.get('CVC_FUZZ_EXAMPLES', default))
