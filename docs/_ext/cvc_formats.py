"""
Sphinx extension: the file formats and JSON outputs, written from the code that reads them.

At ``builder-inited`` it writes, under ``reference/``:

- ``layout_file.md``, ``tolerance_file.md``, ``coefficient_file.md``: each file's fields. The
  fields a reader knows are asked of the reader itself (a field it does not know makes it
  list those it does); whether each may be left out, and what it says to a bad value, are
  the reader's own answers to a probe document. Only the meaning of each field is written
  here, and a field the reader knows without a meaning here, or a meaning for a field it
  does not know, is a build warning (an error under ``-W``).
- ``limits.md``: the range, unit and reason of every number the package accepts, from the
  one table every reader checks (``cvc_balance/physics/limits.py``).
- ``json_outputs.md``: what each command prints with ``--json``, run on the bundled bags
  and layouts at build time, as an outline of its fields with their values there; and the
  fleet tables' columns, from their Arrow schemas.

Nothing here is copied from the code by hand, so these pages cannot drift from it.
"""

import contextlib
import copy
import io
import json
import os
from pathlib import Path
import re
import tempfile

from cvc_reference import _escape, write_generated
from sphinx.util import logging

LOG = logging.getLogger(__name__)
ROOT = Path(__file__).resolve().parents[2]


def _md(text):
    """Return ``text`` as inline code, safe in Markdown (backticks doubled where needed)."""
    text = str(text)
    return f'`` {text} ``' if '`' in text else f'`{text}`'


def _known(message):
    """Return the field names a reader lists in its 'unknown field ... (known: a, b)'."""
    found = re.search(r'\(known: ([^)]*)\)', message or '')
    return [name.strip() for name in found[1].split(',')] if found else None


# -- layouts ---------------------------------------------------------------------------

LAYOUT_PROBE = {
    'name': 'probe', 'description': 'a rotor to probe the reader with',
    'components': [{'name': 'c', 'mass': 1.0, 'radius': 0.5, 'angle_deg': 0.0, 'z': 0.0}],
    'supports': [{'name': 'front', 'z': -0.1,
                  'bearing': {'C': 180000.0, 'type': 'ball', 'X': 0.35, 'Y': 0.57, 'e': 1.14,
                              'a1': 1.0, 'limit_speed': 60.0}},
                 {'name': 'rear', 'z': 0.1, 'axial': True}],
    'gravity': [0.0, -9.80665, 0.0],
    'balancing': {
        'planes': [-0.1, 0.1], 'correction_radius': 0.5, 'grade': 6.3, 'service_speed': 10.0,
        'sites': {'rotation': 'positive',
                  'I': {'angles_deg': [0, 90, 180, 270], 'radius': 0.5, 'masses': [0.1, 0.2],
                        'stack': 2, 'first_hole_angle_deg': 0, 'numbering': 'with_rotation'},
                  'II': {'angles_deg': [0, 90, 180, 270], 'radius': 0.5, 'masses': [0.1]}}},
}
"""A valid layout with every section: each probe changes one field of it."""

SHAPES = {
    'point': {},
    'cylinder': {'radius': 0.1, 'length': 0.2},
    'tube': {'inner_radius': 0.1, 'outer_radius': 0.2, 'length': 0.3},
    'box': {'size': [0.1, 0.2, 0.3]},
    'sphere': {'radius': 0.1},
}
"""A valid shape of each type the reader knows (checked against its list)."""

LAYOUT_SECTIONS = [
    ('layout', (), 'The layout', 'The top level of the file.', {
        'name': ('the layout\'s name: printed with every result, in the diagnostics and '
                 'the bags', ''),
        'description': ('free text', 5),
        'components': ('the components bolted to the rotor, at least one (below)', []),
        'supports': ('one or two supports (bearings), below', [{'name': 'a', 'z': 0}] * 3),
        'gravity': ('m/s^2 in the stator frame (default `[0, -9.80665, 0]`: stator Y up); '
                    'a gantry tilted about stator X adds a Z part', [0, 1]),
        'balancing': ('how the rotor is judged and corrected (below)', 'G 6.3'),
    }),
    ('component', ('components', 0), 'A component',
     'One item of `components`: a part\'s mass and where its centre of mass is, in '
     'cylindrical vector components (R, theta, z) of the rotor frame.', {
         'name': ('unique among the components', ''),
         'mass': ('kg, > 0', -1),
         'radius': ('m, >= 0: the distance of the centre of mass from the spin axis', -0.62),
         'angle': ('rad: theta, the angle of the centre of mass from rotor X toward rotor Y; '
                   'give `angle` or `angle_deg`, exactly one', 1e10, {'angle_deg': None}),
         'angle_deg': ('degrees: theta, as `angle`', 'ninety'),
         'z': ('m: the axial position of the centre of mass (default 0)', 1e300),
         'shape': ('the body, for its own inertia (below); without `shape` or `inertia` the '
                   'component is a point mass', {'type': 'cone'}),
         'inertia': ('instead of `shape`: the inertia tensor about the centre of mass (below)',
                     {'ixx': 1, 'iyy': 1, 'izz': 5, 'ixy': 0, 'ixz': 0, 'iyz': 0}),
     }),
    ('shape', ('components', 0, 'shape'), 'A shape',
     'A component\'s `shape`: `type` and that type\'s lengths (m), centred on the '
     'component\'s centre of mass, in its own frame (x radial, y tangential, z axial). '
     'A solid of the component\'s mass; `axis` (`radial`, `tangential` or `axial`, default '
     'axial) turns a cylinder or a tube.', {
         'type': ('`point`, `cylinder` (solid), `tube`, `box` or `sphere`', 'cone'),
         'radius': ('m, > 0: a cylinder\'s or a sphere\'s radius', -0.1),
         'length': ('m, > 0: a cylinder\'s or a tube\'s length along its axis', 0),
         'inner_radius': ('m, > 0: a tube\'s bore', -1),
         'outer_radius': ('m, > inner_radius: a tube\'s outside', -1),
         'size': ('m, three lengths > 0: a box\'s (radial, tangential, axial) sides', [1, 2]),
         'axis': ('`radial`, `tangential` or `axial` (default): a cylinder\'s or tube\'s axis',
                  'up'),
     }),
    ('inertia', ('components', 0, 'inertia'), 'A given inertia',
     'A component\'s `inertia`, instead of a shape: the six elements of its inertia tensor '
     '(kg m^2) about its centre of mass in its own frame (x radial, y tangential, z axial), '
     'as URDF gives them: the products are tensor elements, `ixy` = -integral of x y dm. '
     'They must be a body\'s (principal moments >= 0, triangle inequality).', {
         name: ('kg m^2', 'heavy') for name in ('ixx', 'iyy', 'izz', 'ixy', 'ixz', 'iyz')
     }),
    ('support', ('supports', 0), 'A support',
     'One item of `supports`: a bearing. With one support the load is its force and its '
     'tilting moment; with two, a force at each, and one of them takes the axial force.', {
         'name': ('a ROS name token (letters, digits, _): it names the topics '
                  '`supports/<name>/load` and `supports/<name>/measured_load`', '1st'),
         'z': ('m: its axial position', 'front'),
         'axial': ('`true` on exactly one of two supports: it takes the axial force '
                   '(default false)', 'yes'),
         'bearing': ('what the bearing is, for its ISO 281 rating life (below; without it no '
                     'life is computed for this support)', 'SKF 6012'),
     }),
    ('bearing', ('supports', 0, 'bearing'), 'A bearing',
     'A support\'s `bearing`: ISO 281\'s basic rating life from the loads on it (the docs\' '
     '"Bearing life"). A layout without bearings keeps its digest.', {
         'C': ('N, > 0: the basic dynamic load rating, from the maker\'s catalogue', 0),
         'type': ('`ball` or `roller` (default ball): the life exponent 3 or 10/3', 'needle'),
         'X': ('the radial load factor of P = X Fr + Y Fa (default 1)', -1),
         'Y': ('the axial load factor (default 0: radial only)', -1),
         'e': ('the Fa / Fr beyond which X and Y hold; up to it P = Fr (default: always)', 0),
         'a1': ('the life adjustment factor for reliability (default 1: L10, 90 %)', 2),
         'limit_speed': ('rad/s: the maker\'s limiting speed (default: not said)', -1),
     }),
    ('balancing', ('balancing',), 'Balancing',
     'How the rotor is judged (ISO 21940-11) and corrected. Optional.', {
         'planes': ('m: `[z_I, z_II]`, the correction planes I < II (default: the two '
                    'supports\' z)', [0.1, -0.1]),
         'correction_radius': ('m, > 0: where correction masses go (default: the largest '
                               'component radius)', 0),
         'grade': ('ISO 21940-11 balance quality grade G, mm/s (default 6.3)', 0),
         'service_speed': ('rad/s: the maximum service speed, where the balance is judged '
                           '(default: none: the top speed seen)', -23.27),
         'sites': ('where correction weights can go, and the kit (below); needs two planes',
                   [0, 15, 30]),
     }),
    ('sites', ('balancing', 'sites'), 'Weight sites',
     '`balancing.sites`: per correction plane the threaded holes or weight-stack sites and '
     'the kit of weights (field balancing plans at these). A layout without sites keeps the '
     'digest it had before sites existed.', {
         'I': ('plane I\'s sites (below)', [0, 90]),
         'II': ('plane II\'s sites (below)', 'all'),
         'rotation': ('`positive` (the rotor turns from rotor X toward rotor Y) or '
                      '`negative`: needed when holes are numbered', 'clockwise'),
     }),
    ('plane sites', ('balancing', 'sites', 'I'), 'One plane\'s sites',
     '`balancing.sites.I` and `.II`.', {
         'angles': ('rad: the sites\' angles from rotor X; `angles` or `angles_deg`, exactly '
                    'one; 1-720 sites, no two at one angle', [0, 0], {'angles_deg': None}),
         'angles_deg': ('degrees: as `angles`', []),
         'radius': ('m, > 0: where the weights\' centres are', 0),
         'masses': ('kg: the weight sizes of the kit, 1-20 sizes, each once', [0.1, 0.1]),
         'stack': ('how many weights may stack on one site, a whole number 1-20 (default 1)',
                   0),
         'first_hole_angle_deg': ('degrees: the angle of hole number 1 (one of the sites); '
                                  'with `numbering`, holes are named by number', 7),
         'numbering': ('`with_rotation` or `against_rotation`: which way the hole numbers run '
                       'from hole 1', 'clockwise'),
     }),
]
"""(name, path in the probe, heading, text, {field: (meaning, a bad value[, other changes])})
per section: the other changes (None: a field removed) go with the bad value, for a field
that excludes another."""


def _layout_answer(document):
    """Return the layout reader's one-line refusal of ``document``, or None if it takes it."""
    from cvc_balance.physics.layout import LayoutError
    from cvc_balance.physics.layout_file import layout_from_text
    try:
        layout_from_text(json.dumps(document))
    except LayoutError as error:
        return str(error)
    return None


def _at(document, path):
    for part in path:
        document = document[part]
    return document


def _probe(answer, base, path, change):
    """Return ``answer`` of ``base`` with the mapping at ``path`` updated (None: removed)."""
    document = copy.deepcopy(base)
    section = _at(document, path)
    for key, value in change.items():
        if value is None:
            section.pop(key, None)
        else:
            section[key] = value
    return answer(document)


def _layout_base(section):
    """Return the probe layout, with a shape or an inertia on its component for those sections."""
    base = copy.deepcopy(LAYOUT_PROBE)
    if section == 'shape':
        base['components'][0]['shape'] = {'type': 'cylinder', 'radius': 0.1, 'length': 0.2}
    if section == 'inertia':
        base['components'][0]['inertia'] = {'ixx': 1.0, 'iyy': 1.0, 'izz': 1.5, 'ixy': 0.0,
                                            'ixz': 0.0, 'iyz': 0.0}
    return base


def _shape_fields():
    """Return {shape type: [its fields]} as the reader lists them."""
    base = _layout_base('shape')
    message = _probe(_layout_answer, base, ('components', 0, 'shape'), {'type': 'no such'})
    kinds = re.search(r'expected one of (.*)$', message or '')
    found = {}
    for kind in (kinds[1].split(', ') if kinds else []):
        spec = {'type': kind, **SHAPES.get(kind, {}), 'not_a_field': 1}
        found[kind] = _known(_probe(_layout_answer, base, ('components', 0), {'shape': spec}))
    if set(found) != set(SHAPES):
        LOG.warning(f'layout shapes: the reader knows {sorted(found)}, this page {sorted(SHAPES)}')
    return found


def _field_lines(answer, base, path, fields, known, required_word='missing field'):
    """Return definition-list lines, one entry per field, with the reader's own answers."""
    lines = []
    for name in known:
        meaning, bad, *others = fields.get(name, ('', None))
        left_out = _probe(answer, base, path, {name: None})
        if left_out is None:
            need = 'May be left out.'
        elif required_word in left_out:
            need = 'Required.'
        else:
            need = f'Left out: {_md(left_out)}.'
        said = _probe(answer, base, path, {**(others[0] if others else {}), name: bad})
        if said is None:
            LOG.warning(f'{path}: the bad value {bad!r} of {name} is taken by the reader: '
                        'give this page one it refuses')
            said = '(taken)'
        value = json.dumps(bad)
        lines += [f'{_md(name)}', f': {meaning}. {need} A bad value, `{name}: {value}`, is '
                  f'refused: {_md(said)}', '']
    return lines


def _check_fields(where, known, fields):
    if known is None:
        LOG.warning(f'{where}: the reader did not list the fields it knows')
        return []
    if set(known) != set(fields):
        LOG.warning(f'{where}: the reader knows {sorted(known)}, this page describes '
                    f'{sorted(fields)}')
    return known


def layout_page():
    """Return the Markdown of the layout file format."""
    from cvc_balance.physics.layout import LayoutError  # noqa: F401 (the reader is importable)
    lines = [
        '# Layout file', '',
        'A layout says what is bolted to the rotor: each component\'s mass and where its '
        'centre of mass is, as cylindrical vector components (radius R, angle theta, axial '
        'position z) in the rotor frame, its body for its own inertia, the supports, gravity, '
        'and how the rotor is judged and corrected. YAML or JSON (a JSON text is read as '
        'columns, fast, for layouts of millions of components). Unknown fields are errors, '
        'so a typo never passes silently; every error is one line naming the component and '
        'the field, and `cvc-balance` exits 2 on it. The node takes the same text on its '
        '`layout` topic.', '',
        'This page is written at build time from the reader itself '
        '(`cvc_balance/physics/layout.py`, `layout_file.py`): the fields it knows, which it '
        'needs, and its answer to a bad value of each, asked of it on a small layout; every '
        'range it says is from the one table of [ranges](limits.md). '
        'Frames, signs and units: [frames](../explanation/frames.md). A valid layout can '
        'still hold a unit mistake (a radius in mm): those get warnings, see '
        '[plausibility warnings](../explanation/verdict.md#plausibility-warnings).', '',
        'The demo gantry with field-balancing sites, `config/ct_gantry_field.yaml`:', '',
        '```{literalinclude} ../../config/ct_gantry_field.yaml', ':language: yaml', '```', '']
    shapes = _shape_fields()
    for name, path, heading, text, fields in LAYOUT_SECTIONS:
        base = _layout_base(name)
        if name == 'shape':
            known = list(dict.fromkeys(f for kind in shapes.values() for f in kind or []))
        else:
            known = _known(_probe(_layout_answer, base, path, {'not_a_field': 1}))
        known = _check_fields(f'layout {name}', known, fields)
        lines += [f'## {heading}', '', text, '']
        if name == 'shape':
            lines += ['| type | its fields |', '|---|---|']
            lines += [f'| `{kind}` | {", ".join(_md(f) for f in (found or []) if f != "type")} |'
                      for kind, found in shapes.items()]
            lines.append('')
            for field_name in known:
                meaning, bad = fields.get(field_name, ('', None))
                spec = ({'type': bad} if field_name == 'type' else
                        {'type': next(k for k, f in shapes.items() if field_name in (f or [])),
                         **SHAPES[next(k for k, f in shapes.items()
                                       if field_name in (f or []))], field_name: bad})
                said = _probe(_layout_answer, base, ('components', 0), {'shape': spec})
                if said is None:
                    LOG.warning(f'layout shape: the bad value {bad!r} of {field_name} is taken')
                lines += [_md(field_name), f': {meaning}. A bad value, `{field_name}: '
                          f'{json.dumps(bad)}`, is refused: {_md(said)}', '']
            continue
        lines += _field_lines(_layout_answer, base, path, fields, known)
    return '\n'.join(lines)


# -- tolerance files -------------------------------------------------------------------

TOLERANCE_FIELDS = {
    'mass': ('kg, >= 0: +- about the layout\'s mass, less than the mass', -0.1),
    'radius': ('m, >= 0: +- about the layout\'s radius (moves the centre of mass along its '
               'radial line)', 'tight'),
    'angle_deg': ('degrees, 0-180: +- about the layout\'s angle; `angle_deg` or `angle`, '
                  'not both', 270),
    'angle': ('rad, as `angle_deg`', -1, {'angle_deg': None}),
    'z': ('m, >= 0: +- about the layout\'s z', float('nan')),
    'distribution': ('`normal` (default: the tolerance is 3 sigma and a part outside it is '
                     'rejected at inspection, so draws are a normal truncated at +-3 sigma) '
                     'or `uniform` (the tolerance is the half-width)', 'gaussian'),
}


def _tolerance_answer(document):
    from cvc_balance.design.tolerances import tolerances_from_text, ToleranceError
    from cvc_balance.physics.layout_file import load_layout
    layout = load_layout(ROOT / 'config' / 'ct_gantry.yaml')
    try:
        tolerances_from_text(json.dumps(document), layout, 'tolerances')
    except ToleranceError as error:
        return str(error)
    return None


def tolerance_page():
    """Return the Markdown of the tolerance file format."""
    base = {'default': {'mass': 0.1, 'radius': 0.0005, 'angle_deg': 0.05, 'z': 0.0005,
                        'distribution': 'normal'}}
    known = _known(_probe(_tolerance_answer, base, ('default',), {'not_a_field': 1}))
    known = _check_fields('tolerance entry', known, TOLERANCE_FIELDS)
    unknown_component = _tolerance_answer({'no_such_part': {'mass': 0.1}})
    lines = [
        '# Tolerance file', '',
        'The tolerances of a layout\'s design parameters, for `cvc-balance sensitivity '
        '--tolerances` and `cvc-balance tolerance` ([design for balance]'
        '(../tutorials/design.md)). YAML or JSON: a mapping from the layout\'s component '
        'names, or `default`, to that component\'s tolerances. A component\'s entry '
        'overrides `default` field by field; what neither gives is exact (tolerance 0). '
        f'A name the layout does not have is refused: {_md(unknown_component)}.', '',
        'This page is written at build time from the reader itself '
        '(`cvc_balance/design/tolerances.py`), asked on the demo gantry\'s layout. The '
        'bundled file, `config/ct_gantry_tolerances.yaml`:', '',
        '```{literalinclude} ../../config/ct_gantry_tolerances.yaml', ':language: yaml',
        '```', '', '## The fields of an entry', '']
    lines += _field_lines(_tolerance_answer, base, ('default',), TOLERANCE_FIELDS, known)
    return '\n'.join(lines)


# -- coefficient records ---------------------------------------------------------------

COEFFICIENT_FIELDS = {
    'kind': ('`cvc_balance influence coefficients`', 'layout'),
    'version': ('1', 2),
    'planes': ('the correction planes, in the coefficients\' column order', []),
    'sensors': ('the channels read, in the coefficients\' row order (`front/force_x`, ...)',
                'front'),
    'reading_units': ('each sensor\'s unit (`N` for load cells; default: none)', 'N'),
    'correction_unit': ('the unit of the corrections\' unbalance: `kg m`, or the trial '
                        'mass\'s unit for readings by hand', 1),
    'speed': ('rad/s: the runs\' steady speed (load cells\' coefficients are scaled as the '
              'speed squared to another one; other sensors refused)', -23.27),
    'condition_number': ('of the coefficient matrix, as written (read again from the '
                         'coefficients)', None),
    'coefficients': ('per sensor, per plane: the reading\'s change per unit of unbalance, '
                     '`amplitude` and `phase_deg` for people and `re`, `im` to the bit (they '
                     'must agree)', [[{'amplitude': 1.0}]]),
    'ci95': ('per sensor, per plane: each coefficient\'s 95 % radius, or null', [[-1]]),
    'keep_trial': ('true when the trials were left on from run to run', 'no'),
    'trials': ('per trial run: its plane, mass, angle, radius, the largest change it made '
               'and in standard errors, `too_small`, `weak`', 'all'),
    'runs': ('per run: its role, bag, date, speed, revolutions, window, readings', 'three'),
    'layout': ('`{name, digest}` of the baseline\'s layout', None),
    'model_check': ('the coefficients against the layout\'s physics (load cells on a rigid '
                    'rotor): measured/predicted per plane', None),
    'warnings': ('what the calibration warned of (trials too small to see, ...), repeated by '
                 'every `correct` that uses the record', 'none'),
}


def _coefficient_answer(document):
    from cvc_balance.field.coefficients import calibration_from_mapping, CoefficientsError
    try:
        calibration_from_mapping(json.loads(json.dumps(document)))
    except CoefficientsError as error:
        return str(error)
    return None


def coefficient_page(record_text):
    """Return the Markdown of the coefficient record, with a record calibrate wrote."""
    import yaml
    base = yaml.safe_load(record_text)
    known = _known(_coefficient_answer({**base, 'not_a_field': 1}))
    known = _check_fields('coefficient record', known, COEFFICIENT_FIELDS)
    fields = {k: v for k, v in COEFFICIENT_FIELDS.items() if v[1] is not None}
    lines = [
        '# Coefficient file', '',
        'The influence-coefficient record `cvc-balance calibrate -o FILE` writes (and '
        '`influence -o FILE` from readings by hand), which `correct --coefficients FILE` and '
        '`report --coefficients FILE` read: what a later correction needs and what a reader '
        'needs to trust it. YAML (JSON accepted); read as layouts are: unknown fields, a '
        'wrong `kind`, numbers not finite, rows that do not match and singular coefficients '
        'are refused in one line, exit code 2. The method: '
        '[field balancing](../explanation/field_balancing.md).', '',
        'This page is written at build time: the record below is what `calibrate` wrote of '
        'the bundled runs (the [field balancing tutorial](../tutorials/field_balancing.md)\'s '
        'step 4), and the reader (`cvc_balance/field/coefficients.py`) is asked about each '
        'field.', '', '```yaml', record_text.rstrip(), '```', '', '## The fields', '']
    for name in known:
        if COEFFICIENT_FIELDS.get(name, (None, 0))[1] is None:
            meaning = COEFFICIENT_FIELDS.get(name, ('',))[0]
            lines += [_md(name), f': {meaning}. Informative: not checked when read.', '']
            continue
        lines += _field_lines(_coefficient_answer, base, (), {name: fields[name]}, [name])
    return '\n'.join(lines)


# -- JSON outputs ----------------------------------------------------------------------

JSON_COMMANDS = [
    ('solve', ['solve', 'config/ct_gantry.yaml', '--omega', '23.27', '--json'],
     'The loads and unbalance for one motion sample (SI: N, N m, kg m, kg m^2; `balance` in '
     'g mm and degrees).'),
    ('replay', ['replay', 'bags/loose_bracket.mcap', '--json'],
     'A bag\'s run as one record: per layout segment the verdict of record (`verdict`: '
     'the measured rotor\'s when load cells can tell, its `source` says which), the '
     'layout\'s (`balance`), and the identified unbalance. The fleet\'s table is made of '
     'these records.'),
    ('identify', ['identify', 'bags/loose_bracket.mcap', '--json'],
     'The real rotor\'s unbalance from its load cells, per layout segment: identified, '
     'the layout\'s prediction and the residual, with 95 % radii.'),
    ('info', ['info', 'bags/loose_bracket.mcap', '--json'],
     'What `ros2 bag info` prints, and the machine and layouts (times in ns).'),
    ('trial-weight', ['trial-weight', 'bags/field_baseline.mcap', '--json'],
     'The trial weight per plane before the trial runs.'),
    ('correct', ['correct', 'bags/field_baseline.mcap', '--coefficients', '{coefficients}',
                 '--json'],
     'The corrections of a run: the readings, the coefficients used, the grade before, and '
     'each plan (continuous, split, optimal) with its weights, the residual it leaves and the '
     'grade after. `report --json` prints this object as its `summary`.'),
    ('influence', ['influence', '--baseline', '170@112', '53@78', '--trial', 'I', '1.15@0',
                   '235@94', '58@68', '--trial', 'II', '1.15@0', '185@115', '77@104',
                   '--json'],
     'Influence coefficients and corrections from readings by hand (B&K\'s two-plane '
     'example).'),
    ('sensitivity', ['sensitivity', 'config/ct_gantry.yaml', '--json'],
     'The exact derivatives of the balance for every design parameter, ranked.'),
    ('tolerance', ['tolerance', 'config/ct_gantry.yaml', '--tolerances',
                   'config/ct_gantry_tolerances.yaml', '--samples', '20000',
                   '--target-probability', '0.99', '--json'],
     'The tolerance stack (Monte Carlo, RSS, worst case) and the allocation.'),
    ('balance', ['balance', 'config/ct_gantry.yaml', '--free', 'counterweight_rear.mass',
                 'counterweight_rear.angle', '--json'],
     'Free parameters solved for balance, and how sensitive the solution is.'),
]
"""(command, arguments on bundled inputs, what it is) of each JSON output shown."""


def _run(args):
    """Run ``cvc-balance ARGS`` in the checkout; return its stdout (a warning if it fails)."""
    from cvc_balance.cli import main
    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(ROOT)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(args)
    finally:
        os.chdir(here)
    if code != 0:
        LOG.warning(f'cvc-balance {" ".join(args)} exited {code}: {err.getvalue().strip()}')
    return out.getvalue()


def _rounded(value):
    """Return ``value`` with its floats to 6 significant digits (an example, read by people)."""
    if isinstance(value, float):
        return float(f'{value:.6g}')
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    return value


def _example(value):
    text = json.dumps(_rounded(value))
    return text if len(text) <= 60 else text[:57] + '...'


def outline(value, indent=0):
    """Return Markdown bullet lines of a JSON value's fields, with a value of each."""
    pad = '  ' * indent
    lines = []
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(item, dict) and item:
                lines.append(f'{pad}- `{key}`: object')
                lines += outline(item, indent + 1)
            elif isinstance(item, list) and item and isinstance(item[0], (dict, list)):
                lines.append(f'{pad}- `{key}`: list of {len(item)}, each:')
                lines += outline(item[0], indent + 1)
            else:
                lines.append(f'{pad}- `{key}`: {_md(_example(item))}')
    elif isinstance(value, list) and value:
        lines.append(f'{pad}- list of {len(value)}, each:')
        lines += outline(value[0], indent + 1)
    return lines


def json_page(coefficients):
    """Return the Markdown of every command's JSON output, and the fleet tables."""
    lines = [
        '# JSON outputs and tables', '',
        'With `--json` a command prints one JSON object (strict: no NaN or Infinity; SI units '
        'unless a field\'s name says `g_mm`, `deg`, ...). Each outline below is what the '
        'command printed of the bundled inputs when this page was built (lists show their '
        'first item), so it is the output\'s shape today, with a value of each field. '
        'Values are rounded to 6 digits here. Commands not shown: `readings --json` (its '
        '`--help` gives the shape), `report --json` (`{report, files, summary}`, the summary '
        'as `correct`\'s), `trends --json`, '
        '`calibrate --json` (the [coefficient record](coefficient_file.md)).', '']
    for name, args, text in JSON_COMMANDS:
        args = [coefficients if a == '{coefficients}' else a for a in args]
        shown = ['cvc-balance'] + ['coefficients.yaml' if a == coefficients else a
                                   for a in args]
        printed = _run(args)
        try:
            value = json.loads(printed)
        except ValueError:
            LOG.warning(f'cvc-balance {name} --json printed no JSON object')
            continue
        lines += [f'## `{name}`', '', text, '', '```text', ' '.join(shown), '```', '']
        lines += outline(value) + ['']
    from cvc_balance.fleet.rows import FAILURE_SCHEMA, RESULT_SCHEMA
    lines += ['## The fleet table', '',
              '`cvc-balance fleet PATH --out RESULTS` writes `RESULTS` (Parquet, zstd), one row '
              'per run and layout segment: the replay record above flattened (run columns '
              'repeated on each segment; the planes as `plane_I_*`, `plane_II_*`; the verdict '
              'of record beside the layout\'s; the load cells\' `identified_*` and '
              '`residual_*`, null without cells). Times are UTC timestamps. Its columns, from '
              'the schema the tool writes (`cvc_balance/fleet/rows.py`):', '',
              '| column | type |', '|---|---|']
    lines += [f'| `{f.name}` | {_md(f.type)} |' for f in RESULT_SCHEMA]
    lines += ['', 'Beside it, `RESULTS.failures.parquet`, one row per bag that could not be '
              'analysed:', '', '| column | type |', '|---|---|']
    lines += [f'| `{f.name}` | {_md(f.type)} |' for f in FAILURE_SCHEMA]
    lines.append('')
    return '\n'.join(lines)


def calibrated(folder):
    """Return (path, text) of the coefficient record calibrate writes of the bundled runs."""
    path = Path(folder) / 'coefficients.yaml'
    _run(['calibrate', 'bags/field_baseline.mcap', 'bags/field_trial_I.mcap',
          'bags/field_trial_II.mcap', '--trial', 'I:0.2@0,0.68', '--trial', 'II:0.2@0,0.68',
          '-o', str(path)])
    return str(path), path.read_text() if path.exists() else ''


def write_pages(app):
    """Write the pages into the source folder's reference/ (ignored by git)."""
    with tempfile.TemporaryDirectory() as scratch:
        coefficients, record = calibrated(scratch)
        write_generated(app.srcdir, {
            'layout_file.md': layout_page(), 'tolerance_file.md': tolerance_page(),
            'coefficient_file.md': coefficient_page(record),
            'json_outputs.md': json_page(coefficients), 'limits.md': limits_page()})


def setup(app):
    """Register the page writer."""
    app.connect('builder-inited', write_pages)
    return {'version': '1', 'parallel_read_safe': True}


# -- ranges ----------------------------------------------------------------------------

def limits_page():
    """Return the Markdown of every quantity's accepted range, from physics/limits.py."""
    import ast
    from cvc_balance.physics import limits
    source = (ROOT / 'cvc_balance' / 'physics' / 'limits.py').read_text(encoding='utf-8')
    sections = {number: line.strip('# -').strip() for number, line
                in enumerate(source.splitlines(), 1) if line.startswith('# -- ')}
    lines = ['# Ranges', '',
             'The range of every number the package accepts from people (in a layout, a '
             'tolerance file, a scenario, an option), with its unit and why: one table, '
             '`cvc_balance/physics/limits.py`, which every reader checks; this page is written '
             'from it at build time. A refusal is one line naming the field, the value, the '
             'range and its unit: the [layout file](layout_file.md) shows the readers\' own '
             'words.']
    body = ast.parse(source).body
    heading = None
    for node, following in zip(body, body[1:] + [None]):
        if not (isinstance(node, ast.Assign) and len(node.targets) == 1
                and isinstance(getattr(limits, node.targets[0].id, None), limits.Limit)):
            continue
        section = max((n for n in sections if n < node.lineno), default=None)
        if section != heading:
            heading = section
            title = sections.get(section, 'others')
            lines += ['', f'## {title[0].upper()}{title[1:]}', '',
                      '| quantity | range | why |', '|---|---|---|']
        limit = getattr(limits, node.targets[0].id)
        what = following.value.value if isinstance(following, ast.Expr) and \
            isinstance(following.value, ast.Constant) else ''
        lines.append(f"| {_md(node.targets[0].id)}: {_escape(' '.join(what.split()))} | "
                     f"{limit.describe()} | {_escape(' '.join(limit.reason.split()))} |")
    return '\n'.join(lines) + '\n'
