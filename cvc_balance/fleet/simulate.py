"""
A simulated fleet: N machines x M runs over months, with drifts, as a tree of bags.

Each machine is the layout as built plus a small mass it does not list (its as-built
unbalance), and one of four histories (by its number, so every kind is in any fleet of
four or more):

* ``slipping counterweight``: the rear counterweight creeps outward at a steady rate
  (mm/day), so its plane's unbalance grows run after run; the layout does not know;
* ``tube swap``: on a date the tube is replaced by one 0.5 kg heavier, and 0.5 kg is
  bolted opposite it; the layout declares both (a new digest, the same declared
  balance), but the real tube is heavier still by an amount the layout misses;
* ``both``: a slipping counterweight and a tube swap;
* ``steady``: nothing changes.

Every run is a short daily check (spin-up, steady at the service speed, coast-down) with
load cells under both supports (:mod:`cvc_balance.bag.scenario`), its time line starting
at the run's date and time (UTC), stamped with its machine id. Runs go to
``DIR/<machine>/<date>T<time>.mcap``, every third as a rosbag2 directory instead, so a
fleet mixes both. The plan returned holds what each run really was (the true
components), for tests and demonstrations to compare with.
"""

import copy
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
import math
from pathlib import Path
import tempfile

import numpy as np

from cvc_balance.bag.scenario import load_scenario, write_bag
from cvc_balance.physics.documents import dump_document, read_document
from cvc_balance.physics.layout_file import MAX_TEXT_BYTES

KINDS = ('slipping counterweight', 'tube swap', 'both', 'steady')
TUBE_STEP = 0.5
"""kg the new tube weighs more than the old, as declared (a correction opposite it)."""
SERVICE_SPEED = 23.27
"""rad/s of the simulated checks when the layout names no service speed."""


@dataclass
class RunPlan:
    """One simulated run: where it is, when, what the layout said and what was real."""

    path: Path
    when: datetime
    declared: dict           # the layout mapping published on /layout
    true_components: list    # the real rotor's components (mappings)


@dataclass
class MachinePlan:
    """One simulated machine: its history and runs."""

    machine_id: str
    kind: str
    slip_mm_per_day: float    # outward creep of the slipping counterweight (0: none)
    swap: datetime            # the tube swap (None: none)
    tube_extra_kg: float      # what the new tube weighs beyond the layout's declaration
    as_built: dict            # the mass the layout does not list
    runs: list = field(default_factory=list)


def simulate_fleet(layout_path, directory, machines=20, runs=5, days=180.0,
                   start='2026-01-05T08:00:00', seed=0, rate=100.0, cell_rate=100.0,
                   counterweight='counterweight_rear', tube='xray_tube', steady=3.0):
    """
    Write a fleet's bags under ``directory``; return [MachinePlan].

    ``layout_path``: the layout of every machine (a layout file with components named
    ``counterweight`` and ``tube``); ``days``: span of the runs; ``start``: the first
    run's date (ISO 8601, UTC); ``rate``, ``cell_rate``: encoder and load-cell samples/s;
    ``steady``: seconds of each run at the service speed (between a spin-up and a coast-down
    at 12 rad/s^2).
    """
    layout = read_document(layout_path, MAX_TEXT_BYTES)
    if not isinstance(layout, dict) or not isinstance(layout.get('components'), list):
        raise ValueError(f'{layout_path}: not a layout (a mapping with a list of components)')
    names = [c.get('name') for c in layout['components'] if isinstance(c, dict)]
    for name in (counterweight, tube):
        if name not in names:
            raise ValueError(f'{layout_path}: no component {name!r} (the simulated fleet '
                             'moves a counterweight and swaps a tube)')
    if machines < 1 or runs < 1 or not days > 0 or not steady > 0:
        raise ValueError('a fleet needs machines >= 1, runs >= 1, days > 0 and steady > 0')
    speed = (layout.get('balancing') or {}).get('service_speed') or SERVICE_SPEED
    first = datetime.fromisoformat(start).replace(tzinfo=timezone.utc)
    rng = np.random.default_rng(seed)
    directory = Path(directory)
    plans = []
    with tempfile.TemporaryDirectory() as scratch:
        for i in range(machines):
            plan = _machine(i, rng, first, days, layout)
            plans.append(plan)
            spacing = days / max(runs - 1, 1)
            for k in range(runs):
                when = first + timedelta(days=k * spacing,
                                         minutes=float(rng.uniform(0, 90)) + 7 * i)
                declared, true = _state(layout, plan, when, first, counterweight, tube)
                folder = directory / plan.machine_id
                folder.mkdir(parents=True, exist_ok=True)
                name = when.strftime('%Y-%m-%dT%H%M%S')
                path = folder / (name if k % 3 == 2 else f'{name}.mcap')
                spec = _scenario(plan, declared, true, when, rate, cell_rate, speed,
                                 seed * 100003 + i * 101 + k, steady)
                spec_path = Path(scratch) / 'run.yaml'
                spec_path.write_text(dump_document(spec), encoding='utf-8')
                write_bag(load_scenario(spec_path), path, machine_id=plan.machine_id)
                plan.runs.append(RunPlan(path, when, declared,
                                         true['components']))
    return plans


def _machine(i, rng, first, days, layout):
    kind = KINDS[i % len(KINDS)]
    slip = float(rng.uniform(0.005, 0.025)) if kind in ('slipping counterweight', 'both') \
        else 0.0
    swap = first + timedelta(days=float(rng.uniform(0.35, 0.65)) * days) \
        if kind in ('tube swap', 'both') else None
    extra = float(rng.uniform(0.2, 0.6)) if swap is not None else 0.0
    planes = (layout.get('balancing') or {}).get('planes') or [-0.12, 0.12]
    as_built = {'name': 'as_built', 'mass': round(float(rng.uniform(0.02, 0.1)), 4),
                'radius': 0.6, 'angle_deg': round(float(rng.uniform(0, 360)), 2),
                'z': round(float(rng.uniform(min(planes), max(planes))), 4)}
    return MachinePlan(f'gantry-{i + 1:04d}', kind, slip, swap, extra, as_built)


def _state(layout, plan, when, first, counterweight, tube):
    """Return (declared layout, true layout) mappings of ``plan``'s machine at ``when``."""
    declared = copy.deepcopy(layout)
    swapped = plan.swap is not None and when >= plan.swap
    if swapped:
        # The new tube is 0.5 kg heavier; the service engineer bolts 0.5 kg opposite it,
        # at its radius and z, and declares both: the declared balance is as before.
        part = next(c for c in declared['components'] if c['name'] == tube)
        part['mass'] = round(part['mass'] + TUBE_STEP, 6)
        opposite = (part.get('angle_deg', 0.0) if 'angle' not in part
                    else math.degrees(part['angle'])) + 180.0
        declared['components'].append({'name': 'tube_swap_correction', 'mass': TUBE_STEP,
                                       'radius': part['radius'], 'angle_deg': opposite,
                                       'z': part.get('z', 0.0)})
    true = copy.deepcopy(declared)
    true['components'].append(dict(plan.as_built))
    elapsed = (when - first).total_seconds() / 86400.0
    moving = next(c for c in true['components'] if c['name'] == counterweight)
    moving['radius'] = moving['radius'] + plan.slip_mm_per_day * 1e-3 * elapsed
    if swapped:
        part = next(c for c in true['components'] if c['name'] == tube)
        part['mass'] = part['mass'] + plan.tube_extra_kg
    return declared, true


def _scenario(plan, declared, true, when, rate, cell_rate, speed, seed, steady):
    """Return the scenario of one run: a short check at the service speed, load cells."""
    hidden = [{'at': 0.0, 'add': dict(plan.as_built)}]
    by_name = {c['name']: c for c in declared['components']}
    for component in true['components']:
        before = by_name.get(component['name'])
        if before is None:
            continue
        changed = {k: v for k, v in component.items() if k in ('mass', 'radius')
                   and v != before.get(k)}
        if changed:
            hidden.append({'at': 0.0, 'set': {'component': component['name'], **changed}})
    supports = [s['name'] for s in declared.get('supports', [])]
    return {
        'name': f'{plan.machine_id} {when.isoformat()}',
        'layout': declared, 'joint_name': 'gantry_joint', 'rate': rate, 'seed': seed,
        'start': when.timestamp(),
        'noise': {'angle': 1.0e-4, 'speed': 0.005},
        'profile': [{'type': 'spin_up', 'to': speed, 'alpha': 12.0},
                    {'type': 'steady', 'duration': steady},
                    {'type': 'coast_down', 'to': 0.0, 'alpha': -12.0}],
        'hidden': hidden,
        'load_cells': {'rate': cell_rate, 'noise': 15.0,
                       'bias': {name: [100.0 * (j + 1), -50.0, 3.0]
                                for j, name in enumerate(supports)}},
    }
