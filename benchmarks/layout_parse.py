"""
A big layout from text to a model in force: time of each step, 10^6 components as JSON.

Prints, for layouts of point masses (and with ``--bodies F``, a fraction F of them shaped)
written as JSON (compact and indented): the text's size; the best wall-clock time of
:func:`layout_from_text` (read as columns), of the digest, of
:meth:`RotorModel.from_layout` (the exact aggregation included), of the plausibility
warnings, and of the node's whole :class:`PreparedLayout` (all of these, as the node's
layout worker does them); with ``--careful``, the same text through the careful reader
(json.loads, a Component per item), as before the columns. Load average before and after.

    ./dev.sh run python benchmarks/layout_parse.py [--components N] [--bodies F]
        [--repeat K] [--careful]
"""

import argparse
from contextlib import nullcontext
from dataclasses import replace
import gc
import json
import math
import os
import time
from unittest import mock

import numpy as np

from cvc_balance.physics import layout_file
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout_file import layout_from_text
from cvc_balance.physics.plausibility import layout_warnings
from cvc_balance.ros.balance_monitor import PreparedLayout


def layout_text(n, bodies, indent, seed=0):
    """JSON text of n random components, a fraction ``bodies`` of them boxes."""
    rng = np.random.default_rng(seed)
    mass, radius = rng.uniform(0.1, 60.0, n), rng.uniform(0.0, 0.8, n)
    angle, z = rng.uniform(0.0, 2 * math.pi, n), rng.uniform(-0.3, 0.3, n)
    shaped = rng.random(n) < bodies
    components = []
    for k in range(n):
        item = {'name': f'c{k}', 'mass': float(mass[k]), 'radius': float(radius[k]),
                'angle': float(angle[k]), 'z': float(z[k])}
        if shaped[k]:
            item['shape'] = {'type': 'box', 'size': [0.1, 0.2, 0.05]}
        components.append(item)
    doc = {'name': 'big', 'components': components,
           'supports': [{'name': 'front', 'z': -0.4}, {'name': 'rear', 'z': 0.4, 'axial': True}]}
    return json.dumps(doc, indent=1 if indent else None)


def best(repeat, work):
    """Best wall-clock time of ``work()`` over ``repeat`` runs, s, and its last result."""
    times, result = [], None
    for _ in range(repeat):
        result = None
        gc.collect()
        start = time.perf_counter()
        result = work()
        times.append(time.perf_counter() - start)
    return min(times), result


def steps(text, repeat):
    """Return the time of each step, s (best of ``repeat``)."""
    read, layout = best(repeat, lambda: layout_from_text(text))
    # A copy of the layout has its digest to compute (the layout's own is kept once made).
    digest, _ = best(repeat, lambda: replace(layout).digest())
    model, _ = best(repeat, lambda: RotorModel.from_layout(layout))
    warnings, _ = best(repeat, lambda: layout_warnings(layout))
    prepared, _ = best(repeat, lambda: PreparedLayout(text, 'benchmark'))
    return {'read': read, 'digest': digest, 'model': model, 'warnings': warnings,
            'prepared': prepared}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--components', type=int, default=1_000_000)
    parser.add_argument('--bodies', type=float, default=0.0,
                        help='fraction of the components that are shaped (boxes)')
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--careful', action='store_true',
                        help='also time the careful reader (json.loads, a Component each)')
    args = parser.parse_args()
    print(f'{args.components} components ({args.bodies:.0%} boxes, the rest point masses) '
          f'as JSON; best of {args.repeat}; 2 cores, load average '
          f'{os.getloadavg()[0]:.1f} at the start')
    print(f'{"text":>22} {"MB":>6} {"reader":>15} {"read":>7} {"digest":>7} {"model":>7} '
          f'{"warn":>7} {"in force":>9}')
    for indent in (False, True):
        text = layout_text(args.components, args.bodies, indent)
        label = 'indented' if indent else 'compact'
        readers = [('columns', None)]
        if args.careful:
            readers.append(('careful', lambda text: None))
        for reader, replacement in readers:
            with mock.patch.object(layout_file, '_read_columns', replacement) \
                    if replacement else nullcontext():
                t = steps(text, args.repeat)
            print(f'{label:>22} {len(text) / 1e6:6.0f} {reader:>15} {t["read"]:7.2f} '
                  f'{t["digest"]:7.2f} {t["model"]:7.2f} {t["warnings"]:7.2f} '
                  f'{t["prepared"]:9.2f}')
    print(f'load average {os.getloadavg()[0]:.1f} at the end; times in s; "in force": the '
          "node's PreparedLayout (read, aggregate, digest, unbalance, warnings)")


if __name__ == '__main__':
    main()
