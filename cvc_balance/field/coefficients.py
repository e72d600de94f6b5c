"""
The influence-coefficient record: a :class:`Calibration` as a mapping and back.

The record (YAML or JSON; the docs' "Coefficient file") holds what a later correction needs
(planes, sensors, the coefficients per sensor and plane as amplitude and phase, their 95 %
radii, the speed and units) and what a reader needs to trust it (the runs it came from,
each trial's visibility, the warnings). No file I/O: the command line reads and writes
the text. :func:`calibration_from_mapping` checks a record as layouts are checked:
unknown fields are errors, numbers finite and bounded, one line naming what is wrong.
"""

import cmath
from dataclasses import replace
import math

import numpy as np

from cvc_balance.field.influence import Calibration, checked_condition, CHI2_2DOF_95, Trial
from cvc_balance.physics.layout import MAX_MAGNITUDE, short

AGREE = 1e-6
"""How closely a record's re, im must agree with its amplitude and phase (relative)."""
KIND = 'cvc_balance influence coefficients'
VERSION = 1
FIELDS = ('kind', 'version', 'planes', 'sensors', 'reading_units', 'correction_unit', 'speed',
          'condition_number', 'coefficients', 'ci95', 'keep_trial', 'trials', 'runs',
          'layout', 'model_check', 'warnings')


class CoefficientsError(ValueError):
    """A coefficient record that cannot be used; ``str()`` is one line naming what."""


def condition_number(matrix, what='the coefficients'):
    """Return the condition number of coefficients; CoefficientsError when singular."""
    try:
        return checked_condition(matrix, what)
    except ValueError as error:
        raise CoefficientsError(str(error)) from None


def polar(value):
    """Return a complex value as {amplitude, phase_deg} (phase in [0, 360))."""
    value = complex(value)
    return {'amplitude': abs(value), 'phase_deg': math.degrees(cmath.phase(value)) % 360.0}


def exact(value):
    """Return a coefficient as {amplitude, phase_deg} for people and {re, im} to the bit."""
    value = complex(value)
    return {**polar(value), 're': value.real, 'im': value.imag}


def calibration_mapping(calibration, reading_units, correction_unit, speed=None,
                        keep_trial=False, trials=(), runs=(), layout=None, model_check=None):
    """
    Return the record of ``calibration`` as plain data (YAML/JSON-able).

    ``reading_units`` one per sensor; ``correction_unit`` the unbalance unit ('kg m', or
    the trial's mass unit); ``speed`` rad/s or None; ``trials`` the
    :class:`~cvc_balance.field.influence.Trial` per run; ``runs`` per run identity
    mappings; ``layout`` {name, digest} or None; ``model_check`` the coefficients
    against the layout's physics (plain data) or None.
    """
    ci95 = None if calibration.ci95 is None else np.asarray(calibration.ci95).tolist()
    checks = []
    for check, trial in zip(calibration.checks, trials):
        checks.append({'run': check.run + 1, 'plane': trial.plane, 'mass': float(trial.mass),
                       'angle_deg': math.degrees(trial.angle) % 360.0,
                       'radius': float(trial.radius),
                       'largest_change': float(check.change),
                       'snr': None if check.snr is None else float(check.snr),
                       'relative_change': float(check.relative),
                       'too_small': bool(check.too_small), 'weak': bool(check.weak)})
    condition = float(calibration.condition)
    return {
        'kind': KIND, 'version': VERSION,
        'planes': list(calibration.planes), 'sensors': list(calibration.sensors),
        'reading_units': list(reading_units), 'correction_unit': correction_unit,
        'speed': None if speed is None else float(speed),
        'condition_number': condition if math.isfinite(condition) else None,
        'coefficients': [[exact(v) for v in row] for row in np.asarray(calibration.matrix)],
        'ci95': ci95, 'keep_trial': bool(keep_trial), 'trials': checks, 'runs': list(runs),
        'layout': layout, 'model_check': model_check,
        'warnings': list(calibration.warnings),
    }


def calibration_from_mapping(data, source='coefficients'):
    """
    Return (Calibration, record) of a record read from YAML/JSON; checks every field used.

    Raises :class:`CoefficientsError`. The condition number is computed again from the
    coefficients; trial checks are not rebuilt (the record's ``trials`` stay as read).
    """
    if not isinstance(data, dict):
        raise CoefficientsError(f'{source}: expected a mapping of fields, got '
                                f'{type(data).__name__}')
    for key in data:
        if key not in FIELDS:
            raise CoefficientsError(f'{source}: unknown field {short(key)} (known: '
                                    f'{", ".join(FIELDS)})')
    if data.get('kind') != KIND:
        raise CoefficientsError(f'{source}: field kind must be {KIND!r}, got '
                                f'{short(data.get("kind"))}: not an influence-coefficient '
                                'record')
    if data.get('version') != VERSION:
        raise CoefficientsError(f'{source}: field version must be {VERSION}, got '
                                f'{short(data.get("version"))}')
    planes = _names(data.get('planes'), f'{source}: field planes')
    sensors = _names(data.get('sensors'), f'{source}: field sensors')
    rows = data.get('coefficients')
    if not isinstance(rows, list) or len(rows) != len(sensors):
        raise CoefficientsError(f'{source}: field coefficients needs one row per sensor '
                                f'({len(sensors)}), got {short(rows)}')
    matrix = np.zeros((len(sensors), len(planes)), complex)
    for s, row in enumerate(rows):
        where = f'{source}: field coefficients[{s}]'
        if not isinstance(row, list) or len(row) != len(planes):
            raise CoefficientsError(f'{where}: needs one entry per plane ({len(planes)}), '
                                    f'got {short(row)}')
        for j, entry in enumerate(row):
            matrix[s, j] = _polar(entry, f'{where}[{j}]')
    ci95 = data.get('ci95')
    if ci95 is not None:
        values = np.array([[_number(v, f'{source}: field ci95') for v in row]
                           for row in _rows(ci95, len(sensors), len(planes), source)])
        ci95 = values
    units = data.get('reading_units', [''] * len(sensors))
    if not isinstance(units, list) or len(units) != len(sensors) \
            or not all(isinstance(u, str) for u in units):
        raise CoefficientsError(f'{source}: field reading_units needs a text per sensor')
    if not isinstance(data.get('correction_unit', 'kg m'), str):
        raise CoefficientsError(f'{source}: field correction_unit must be text')
    speed = data.get('speed')
    if speed is not None:
        speed = _number(speed, f'{source}: field speed')
        if not speed > 0.0:
            raise CoefficientsError(f'{source}: field speed must be > 0 rad/s, got {speed:g}')
    warnings = data.get('warnings', [])
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        raise CoefficientsError(f'{source}: field warnings must be a list of text')
    for key in ('trials', 'runs'):
        if not isinstance(data.get(key, []), list):
            raise CoefficientsError(f'{source}: field {key} must be a list')
    if not isinstance(data.get('keep_trial', False), bool):
        raise CoefficientsError(f'{source}: field keep_trial must be true or false')
    condition = condition_number(matrix, f'{source}: the coefficients')
    calibration = Calibration(tuple(planes), tuple(sensors), matrix, ci95, condition, (),
                              tuple(warnings))
    record = dict(data, reading_units=units, speed=speed,
                  correction_unit=data.get('correction_unit', 'kg m'))
    return calibration, record


def record_trials(record):
    """
    Return the typed trials of a record's ``trials`` as :class:`Trial` (kg, rad, m).

    () when the record has none or any is incomplete (then no mistake can be named).
    """
    trials = []
    for entry in (record or {}).get('trials') or ():
        try:
            values = [float(entry[k]) for k in ('mass', 'angle_deg', 'radius')]
        except (KeyError, TypeError, ValueError):
            return ()
        if not (isinstance(entry.get('plane'), str) and all(map(math.isfinite, values))):
            return ()
        trials.append(Trial(entry['plane'], values[0], math.radians(values[1]), values[2]))
    return tuple(trials)


def _names(value, where):
    if not isinstance(value, list) or not value or len(value) > 1000 \
            or not all(isinstance(v, str) and 0 < len(v) <= 200 and v.isprintable()
                       for v in value):
        raise CoefficientsError(f'{where}: give a list of names, got {short(value)}')
    if len(set(value)) != len(value):
        raise CoefficientsError(f'{where}: each name once')
    return value


def _rows(value, count, width, source):
    if not isinstance(value, list) or len(value) != count or \
            not all(isinstance(r, list) and len(r) == width for r in value):
        raise CoefficientsError(f'{source}: field ci95 needs {count} rows of {width} numbers')
    return value


def _number(value, where):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CoefficientsError(f'{where} must be a number, got {short(value)}')
    if isinstance(value, int) and abs(value) > MAX_MAGNITUDE:
        raise CoefficientsError(f'{where} must be within +-{MAX_MAGNITUDE:g}')
    value = float(value)
    if not math.isfinite(value) or abs(value) > MAX_MAGNITUDE:
        raise CoefficientsError(f'{where} must be finite and within +-{MAX_MAGNITUDE:g}, '
                                f'got {short(value)}')
    return value


def _polar(entry, where):
    if not isinstance(entry, dict) or not {'amplitude', 'phase_deg'} <= set(entry) \
            or not set(entry) <= {'amplitude', 'phase_deg', 're', 'im'} \
            or len({'re', 'im'} & set(entry)) == 1:
        raise CoefficientsError(f'{where}: give {{amplitude, phase_deg}} (and both re, im or '
                                f'neither), got {short(entry)}')
    amplitude = _number(entry['amplitude'], f'{where}.amplitude')
    if amplitude < 0.0:
        raise CoefficientsError(f'{where}.amplitude must be >= 0, got {amplitude:g}')
    phase = _number(entry['phase_deg'], f'{where}.phase_deg')
    value = cmath.rect(amplitude, math.radians(phase))
    if 're' in entry:
        # The exact value calibrate wrote; amplitude and phase are its rounding for people.
        stored = complex(_number(entry['re'], f'{where}.re'), _number(entry['im'], f'{where}.im'))
        if abs(stored - value) > AGREE * max(abs(stored), amplitude):
            raise CoefficientsError(f'{where}: re, im ({stored.real:.6g}, {stored.imag:.6g}) '
                                    f'disagree with amplitude {amplitude:g} at {phase:g} deg: '
                                    'edit both or remove re and im')
        value = stored
    return value


SCALES_AS_SPEED_SQUARED = ('N', 'N m')
"""Reading units of load cells: their 1x grows as the speed squared (rigid rotor)."""
SPEED_AGREES = 1e-3
"""Relative speed difference under which coefficients are taken as they are."""


def at_speed(calibration, record, speed):
    """
    Return (Calibration, note): the coefficients for readings at ``speed`` rad/s.

    A record made at another speed is scaled as the speed squared when every sensor is a
    load cell (N, N m), and said in ``note``; refused (ValueError) when a sensor's scaling
    with speed is not known. No speed on either side: as they are, note ''.
    """
    recorded = (record or {}).get('speed')
    if recorded is None or speed is None or abs(speed / recorded - 1.0) <= SPEED_AGREES:
        return calibration, ''
    units = list((record or {}).get('reading_units') or [])
    unknown = [n for n, u in zip(calibration.sensors, units) if u not in SCALES_AS_SPEED_SQUARED]
    if unknown or len(units) != len(calibration.sensors):
        names = ', '.join(f"{n} ({u!r})" for n, u in zip(calibration.sensors, units)
                          if u not in SCALES_AS_SPEED_SQUARED) or 'their units'
        raise ValueError(f'the coefficients were made at {recorded:.4g} rad/s, the readings at '
                         f'{speed:.4g} rad/s: how {names} scales with speed is not known (a load '
                         'cell in N scales as the speed squared); calibrate at this speed')
    factor = (speed / recorded) ** 2
    scaled = replace(calibration, matrix=np.asarray(calibration.matrix) * factor,
                     ci95=None if calibration.ci95 is None
                     else np.asarray(calibration.ci95) * factor)
    return scaled, (f'the coefficients, made at {recorded:.4g} rad/s, are scaled to the '
                    f'readings\' {speed:.4g} rad/s as the speed squared (x{factor:.4g}; load '
                    'cells of a rigid rotor)')


def plane_unbalance(calibration, readings, sigma):
    """
    Return (u, covariance): the unbalance per plane that readings imply, R = C u.

    ``readings`` complex, one per sensor of ``calibration`` (its unit); ``sigma`` their
    standard errors per x and y component. Weighted least squares (exact with as many
    sensors as planes); ``covariance`` (planes x planes, complex) of u's error per
    component, from the readings' noise and the coefficients' own 95 % radii (each
    coefficient's error moves a reading by it times the plane's u). Units: the record's
    correction unit (kg m from trial runs).
    """
    matrix = np.asarray(calibration.matrix, complex)
    readings = np.asarray(readings, complex)
    variance = np.maximum(np.asarray(sigma, float) ** 2, 1e-300)
    u = None
    for _ in range(2):
        if u is not None and calibration.ci95 is not None:
            coefficient = (np.asarray(calibration.ci95, float) ** 2 / CHI2_2DOF_95) \
                @ (np.abs(u) ** 2)
            variance = np.asarray(sigma, float) ** 2 + coefficient
        weight = 1.0 / np.maximum(variance, 1e-300)
        normal = matrix.conj().T @ (weight[:, None] * matrix)
        covariance = np.linalg.inv(normal)
        u = covariance @ (matrix.conj().T @ (weight * readings))
    return u, covariance
