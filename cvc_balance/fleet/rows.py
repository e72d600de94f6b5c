"""
The fleet's tables: a row per run and layout segment, and a row per failed bag.

A row is the bag's replay record (:func:`cvc_balance.bag.run_summary.analyse_bag`, what
``cvc-balance replay BAG --json`` prints) flattened: run columns repeated on each of its
segments, the segment's numbers, the two correction planes as ``plane_I_*`` and
``plane_II_*`` (the layout's), the verdict of record (``level``, ``verdict``,
``equivalent_grade``: the measured rotor's when its load cells can tell, ``verdict_source``
says which) beside the layout's (``layout_*``), and the load cells' identification as
``identified_*`` and ``residual_*`` (null without cells), and the bearings' life (where the
layout describes them): ``running_hours`` of the segment and ``bearings``, per support its
life used, rating life at the run's duty, mean equivalent load and what the unbalance cost,
measured where the verdict of record is the measured rotor's and its cell could tell
(``source``), else the layout's. Times are UTC timestamps (ns).
Units as in the record: SI, g mm and degrees where the name says so. The schemas are fixed
here, so every run of the tool writes the same columns and DuckDB, pandas or Spark read the
table alike.
"""

import pyarrow as pa

TIME = pa.timestamp('ns', tz='UTC')
PLANES = ('I', 'II')

_RUN = [
    ('digest', pa.string()), ('bag', pa.string()), ('bag_bytes', pa.int64()),
    ('bag_mtime_ns', pa.int64()), ('machine_id', pa.string()), ('machine_source', pa.string()),
    ('run_start', TIME), ('run_end', TIME), ('samples', pa.int64()), ('accepted', pa.int64()),
    ('rejected', pa.int64()), ('dropped', pa.int64()), ('skipped', pa.int64()),
    ('problems', pa.list_(pa.string())), ('segments', pa.int32()),
    ('analysed_at', TIME), ('analysis_seconds', pa.float64()),
]
_SEGMENT = [
    ('segment', pa.int32()), ('layout_name', pa.string()), ('layout_digest', pa.string()),
    ('layout_from', TIME), ('segment_start', TIME), ('segment_end', TIME),
    ('segment_samples', pa.int64()), ('top_speed', pa.float64()), ('peak_load_N', pa.float64()),
    ('peak_support_load_N', pa.map_(pa.string(), pa.float64())),
    ('warnings', pa.list_(pa.string())), ('model', pa.string()),
    ('grade', pa.float64()), ('service_speed', pa.float64()), ('speed_source', pa.string()),
    ('permissible_g_mm', pa.float64()), ('static_g_mm', pa.float64()),
    ('static_angle_deg', pa.float64()),
]
_PLANE = [('z', pa.float64()), ('g_mm', pa.float64()), ('angle_deg', pa.float64()),
          ('permissible_g_mm', pa.float64()), ('fraction', pa.float64()),
          ('correction_mass_kg', pa.float64()), ('correction_angle_deg', pa.float64())]
_VERDICT = [('equivalent_grade', pa.float64()), ('finest_grade_met', pa.float64()),
            ('within_grade', pa.bool_()), ('level', pa.string()), ('verdict', pa.string()),
            ('verdict_source', pa.string()), ('verdict_reason', pa.string()),
            ('disagreement', pa.string()), ('layout_equivalent_grade', pa.float64()),
            ('layout_level', pa.string()), ('layout_verdict', pa.string())]
"""The verdict of record (the measured rotor's when the cells can tell, see
:mod:`cvc_balance.identify.evidence`) and the layout's beside it."""
_IDENTIFIED = [('identified_readings', pa.int64()), ('identified_revolutions', pa.float64()),
               ('identifiable', pa.bool_()), ('fit_rms_N', pa.float64())]
_VECTOR = [('', pa.float64()), ('_angle_deg', pa.float64()), ('_ci95', pa.float64())]
BEARING = pa.struct([('support', pa.string()), ('life_used', pa.float64()),
                     ('l10_hours', pa.float64()), ('equivalent_load_N', pa.float64()),
                     ('unbalance_share', pa.float64()), ('source', pa.string())])
"""One bearing's use in a segment (:mod:`cvc_balance.bag.life_run`'s record, of record)."""
_LIFE = [('running_hours', pa.float64()), ('bearings', pa.list_(BEARING))]

RESULT_SCHEMA = pa.schema(
    _RUN + _SEGMENT
    + [(f'plane_{p}_{name}', kind) for p in PLANES for name, kind in _PLANE] + _VERDICT
    + _IDENTIFIED
    + [(f'{what}_static_kg_m{suffix}', kind) for what in ('identified', 'residual')
       for suffix, kind in _VECTOR]
    + [(f'{what}_plane_{p}_g_mm{suffix}', kind) for what in ('identified', 'residual')
       for p in PLANES for suffix, kind in _VECTOR]
    + [(f'identified_plane_{p}_fraction', pa.float64()) for p in PLANES]
    + [('identified_equivalent_grade', pa.float64()), ('identified_level', pa.string())]
    + _LIFE)
"""Columns of the results table (one row per run and layout segment)."""

FAILURE_SCHEMA = pa.schema([
    ('digest', pa.string()), ('bag', pa.string()), ('bag_bytes', pa.int64()),
    ('bag_mtime_ns', pa.int64()), ('machine_id', pa.string()), ('machine_source', pa.string()),
    ('reason', pa.string()), ('failed_at', TIME)])
"""Columns of the failures table (one row per bag that could not be analysed)."""


def _ns(seconds):
    """Seconds since the epoch (float, None) as integer ns, rounded to the microsecond."""
    return None if seconds is None else int(round(seconds * 1e6)) * 1000


def result_rows(record, digest, bag, stat, machine, analysed_at_ns, seconds):
    """
    Return the rows of one bag's replay record (see the module's description).

    ``stat``: (bytes, mtime ns) of the bag; ``machine``: (machine id, where from);
    ``analysed_at_ns``: when, ns since the epoch; ``seconds``: how long it took.
    """
    run = {
        'digest': digest, 'bag': str(bag), 'bag_bytes': stat[0], 'bag_mtime_ns': stat[1],
        'machine_id': machine[0], 'machine_source': machine[1],
        'run_start': _ns(record['start']), 'run_end': _ns(record['end']),
        'samples': record['samples'], 'accepted': record['accepted'],
        'rejected': record['rejected'], 'dropped': record['dropped'],
        'skipped': record['skipped'], 'problems': list(record['problems']),
        'segments': len(record['segments']), 'analysed_at': analysed_at_ns,
        'analysis_seconds': seconds,
    }
    return [dict(run, **segment_columns(k, segment))
            for k, segment in enumerate(record['segments'])]


def segment_columns(index, segment):
    """Return the columns of one segment of a replay record."""
    row = {
        'segment': index, 'layout_name': segment['layout']['name'],
        'layout_digest': segment['layout']['digest'], 'layout_from': _ns(segment['from']),
        'segment_start': _ns(segment['first_sample']),
        'segment_end': _ns(segment['last_sample']), 'segment_samples': segment['samples'],
        'top_speed': segment['top_speed'], 'peak_load_N': segment['peak_load_N'],
        'peak_support_load_N': list(segment['peak_support_load_N'].items()),
        'warnings': list(segment['warnings']), 'model': segment['model'],
    }
    balance = segment['balance'] or {}
    for key in ('grade', 'service_speed', 'speed_source', 'permissible_g_mm', 'static_g_mm',
                'static_angle_deg'):
        row[key] = balance.get(key)
    verdict = segment['verdict']
    for key in ('equivalent_grade', 'finest_grade_met', 'within_grade', 'level', 'verdict',
                'layout_equivalent_grade', 'layout_level', 'layout_verdict', 'disagreement'):
        row[key] = verdict[key]
    row['verdict_source'], row['verdict_reason'] = verdict['source'], verdict['reason']
    planes = balance.get('planes') or []
    for p, plane in zip(PLANES, planes):
        for key, _ in _PLANE:
            row[f'plane_{p}_{key}'] = plane[key]
    row.update(bearing_columns(segment))
    identified = segment['identified']
    if identified is None:
        return row
    row.update(identified_readings=identified['readings'],
               identified_revolutions=identified['revolutions'],
               identifiable=identified['identifiable'], fit_rms_N=identified['fit']['rms_N'])
    for what in ('identified', 'residual'):
        static = identified[what]['static_unbalance']
        row[f'{what}_static_kg_m'] = static['kg_m']
        row[f'{what}_static_kg_m_angle_deg'] = static['angle_deg']
        row[f'{what}_static_kg_m_ci95'] = static['ci95_kg_m']
        for p, plane in zip(PLANES, identified[what]['planes']):
            row[f'{what}_plane_{p}_g_mm'] = plane['g_mm']
            row[f'{what}_plane_{p}_g_mm_angle_deg'] = plane['angle_deg']
            row[f'{what}_plane_{p}_g_mm_ci95'] = plane['ci95_g_mm']
    grade = identified['grade']
    if grade is not None:
        for p, fraction in zip(PLANES, grade['fractions']):
            row[f'identified_plane_{p}_fraction'] = fraction
        row['identified_equivalent_grade'] = grade['equivalent_grade']
        row['identified_level'] = grade['level']
    return row


def bearing_columns(segment):
    """
    Return a segment's ``running_hours`` and ``bearings`` (null where none is described).

    Each bearing's use of record: measured when the segment's verdict of record is the
    measured rotor's and the bearing's cell told its load, else the layout's.
    """
    first, last = segment['first_sample'], segment['last_sample']
    columns = {'running_hours': None if first is None else (last - first) / 3600.0,
               'bearings': None}
    if segment.get('life'):
        measured = segment['verdict']['source'] == 'measured'
        columns['bearings'] = []
        for record in segment['life']:
            source = 'measured' if measured and record['measured'] is not None else 'layout'
            use = record[source]
            columns['bearings'].append({'support': record['name'], 'source': source,
                                        **{key: use[key] for key in (
                                            'life_used', 'l10_hours', 'equivalent_load_N',
                                            'unbalance_share')}})
    return columns


def failure_row(digest, bag, stat, machine, reason, failed_at_ns):
    """Return the row of a bag that could not be analysed, with the one-line reason."""
    return {'digest': digest, 'bag': str(bag), 'bag_bytes': stat[0], 'bag_mtime_ns': stat[1],
            'machine_id': machine[0], 'machine_source': machine[1], 'reason': reason,
            'failed_at': failed_at_ns}


def table(rows, schema):
    """Return ``rows`` (dicts; missing columns null) as a pyarrow Table of ``schema``."""
    return pa.Table.from_pylist([{name: row.get(name) for name in schema.names}
                                 for row in rows], schema=schema)
