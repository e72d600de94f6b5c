"""
Scenarios against hand calculations, exact fractions, Pinocchio and rosbags (issue 29).

* the exact motion of piecewise constant accelerations, against ``Fraction`` arithmetic;
* what a scenario file gives (defaults, events, hidden changes, a tilt, load cells) and
  every refusal's words;
* the load cells' readings: Pinocchio's RNEA of the true rotor at the exact motion, split
  over the supports by statics, plus each cell's bias (no noise);
* the bag ``write_bag`` writes, decoded by rosbags: layouts, joint states, cells.

Small scenarios (a few hundred samples): milliseconds each.
"""

from fractions import Fraction
import math

from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
import yaml

from cvc_balance.bag.scenario import exact_motion, load_scenario, ScenarioError, write_bag
from independent import PinocchioRotor

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
G = 9.80665
LAYOUT = {
    'name': 'drum', 'gravity': [0.0, -G, 0.0],
    'components': [
        {'name': 'drum', 'mass': 300.0, 'radius': 0.0, 'angle': 0.0,
         'shape': {'type': 'tube', 'inner_radius': 0.6, 'outer_radius': 0.7, 'length': 0.4}},
        {'name': 'tube', 'mass': 40.0, 'radius': 0.55, 'angle_deg': 20.0, 'z': 0.08},
        {'name': 'lump', 'mass': 2.0, 'radius': 0.6, 'angle': 1.0, 'z': -0.1}],
    'supports': [{'name': 'front', 'z': -0.3}, {'name': 'rear', 'z': 0.3, 'axial': True}]}


def write_scenario(folder, **fields):
    """Write a scenario (the drum inline, 100 samples/s, 5 s) with ``fields``; return its path."""
    spec = {'layout': LAYOUT, 'rate': 100,
            'profile': [{'type': 'spin_up', 'to': 10.0, 'alpha': 5.0},
                        {'type': 'steady', 'duration': 1.0},
                        {'type': 'coast_down', 'to': 4.0, 'alpha': -3.0}]}
    spec.update(fields)
    path = folder / 'run.yaml'
    path.write_text(yaml.safe_dump(spec))
    return path


def test_files_that_are_no_scenario(tmp_path):
    """A list, a layout file, an unknown field (the known ones in order), a missing layout."""
    path = tmp_path / 'run.yaml'
    path.write_text('- 1\n')
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == f'{path}: a scenario is a mapping'
    path.write_text(yaml.safe_dump(LAYOUT))
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == (f'{path}: this is a layout file (it has components), not a '
                                  'scenario; a scenario names a layout (layout: FILE) and '
                                  'gives a speed profile, e.g. bags/spin_up_tube_swap.yaml')
    path = write_scenario(tmp_path, speed=3)
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == (f"{path}: unknown field 'speed' (known: events, hidden, "
                                  'joint_name, layout, load_cells, name, noise, profile, '
                                  'rate, seed, start)')
    path = write_scenario(tmp_path, layout='missing.yaml')
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == (f'{path}: field layout: {tmp_path / "missing.yaml"}: cannot '
                                  'read layout: No such file or directory')
    (tmp_path / 'drum.yaml').write_text(yaml.safe_dump(LAYOUT))
    assert load_scenario(write_scenario(tmp_path, layout='drum.yaml')).layouts == \
        [(0.0, LAYOUT)]
