"""
A pytest plugin that checks mutmut's mutants in one process (much faster on a busy machine).

Run from a mutmut work's ``mutants/`` directory (``benchmarks/mutation.py`` makes it), with
the tests mutmut ran::

    cd /tmp/<work>/<module>/mutants
    export MUTANTS_FILE=names.txt RESULTS_FILE=out.tsv PYTHONPATH=.:<repo>/benchmarks
    python -m pytest -p mutants_in_process -q --tb=no -p no:cacheprovider TESTS...

``names.txt``: one mutant a line (as ``mutmut results`` names them). The tests are
collected once; each mutant is selected by ``MUTANT_UNDER_TEST`` and its tests run in
order (``STATS_FILE``: mutmut's ``mutmut-stats.json``, to run only the tests that reach
the mutated function, fastest first, as mutmut does) until one fails: killed, or
``timeout`` past ``MUTANT_LIMIT`` s of CPU time in one test (default 10), else
survived. One line a mutant in ``RESULTS_FILE``: name, status, the test, seconds. The
clean code runs first and must pass. A mutant's tests share their module fixtures (torn
down after its last test), so a fixture made with the mutant serves every test that reads
it, not only the first (mutmut's stats credit a module fixture's calls to the first test
that made it: give no ``STATS_FILE`` to run the whole selection, in the order given, for
each mutant). ``RESET_CACHES``: empty the traced programs before
each mutant (see fresh_programs.py). Module state a mutant leaves behind is not undone:
for modules with caches, set RESET_CACHES or use mutmut.
"""

import json
import os
import signal
import threading
import time

from _pytest.runner import runtestprotocol

LIMIT = float(os.environ.get('MUTANT_LIMIT', '10'))


class TimeOut(BaseException):
    """A test ran past the CPU-time limit."""


def _alarm(*_):
    raise TimeOut()


def _reset_caches():
    from cvc_balance.physics import compensated, inertia
    compensated._COS_SIN.clear()
    compensated._TABLES.clear()
    compensated._LOCAL = threading.local()
    inertia._PROGRAMS.clear()
    inertia._LOCAL = threading.local()


def _chosen(items, stats, mutant):
    """Return the tests of ``mutant``: all, or those that reach its function, fastest first."""
    if stats is None or not mutant:
        return items
    function = mutant.rsplit('__mutmut_', 1)[0]
    wanted = set(stats['tests_by_mangled_function_name'].get(function, ()))
    durations = stats['duration_by_test']
    return sorted((i for i in items if i.nodeid in wanted),
                  key=lambda i: durations.get(i.nodeid, 0.0))


def pytest_runtestloop(session):
    """Run the clean code, then each mutant's tests; write one line a mutant."""
    names = [n.strip() for n in open(os.environ['MUTANTS_FILE']) if n.strip()]
    stats = None
    if os.environ.get('STATS_FILE'):
        with open(os.environ['STATS_FILE']) as stream:
            stats = json.load(stream)
    signal.signal(signal.SIGVTALRM, _alarm)
    with open(os.environ['RESULTS_FILE'], 'a') as out:
        for mutant in [''] + names:
            os.environ['MUTANT_UNDER_TEST'] = mutant
            if os.environ.get('RESET_CACHES'):
                _reset_caches()
            chosen = _chosen(session.items, stats, mutant)
            status, by, started = ('survived' if chosen else 'no tests'), '', time.monotonic()
            for index, item in enumerate(chosen):
                following = chosen[index + 1] if index + 1 < len(chosen) else None
                signal.setitimer(signal.ITIMER_VIRTUAL, LIMIT)
                try:
                    reports = runtestprotocol(item, nextitem=following, log=False)
                except TimeOut:
                    status, by = 'timeout', item.nodeid
                    session._setupstate.teardown_exact(None)
                    break
                finally:
                    signal.setitimer(signal.ITIMER_VIRTUAL, 0)
                if any(report.failed for report in reports):
                    status, by = 'killed', item.nodeid
                    session._setupstate.teardown_exact(None)
                    break
            if not mutant:
                assert status == 'survived', f'the clean code fails {by}'
                continue
            out.write(f'{mutant}\t{status}\t{by}\t{time.monotonic() - started:.2f}\n')
            out.flush()
    return True
