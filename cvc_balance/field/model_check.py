"""
The layout's physics and the measured influence coefficients, each checking the other.

For load cells under the supports of a rigid rotor the influence coefficients follow from
the layout alone: an unbalance u (kg m) added in the correction plane at z adds S = u and
P = z u to the rotor's first moments and products, and the engine's own equations
(:mod:`cvc_balance.physics.engine`, evaluated for a unit point mass at z with the layout's
supports and gravity) give each support's 1x force (and a single support's 1x tilting
moment) per kg m at the run's speed: :func:`predicted_coefficients`.

:func:`check_coefficients` compares them with measured ones plane by plane: the complex
factor k = measured / predicted (weighted least squares over the sensors, each by its
noise). Beyond a factor 3 in amplitude or 45 deg in phase, and beyond the measurement's
own 95 % circle, the two disagree; then every mistake of a catalogue (units, senses,
planes, runs and cells mixed up: :data:`MISTAKES`) turns what was typed into what may
have been, predicts the coefficients that would then be measured, and the one that
explains the measured ones best is named. Radians and SI inside; degrees in the text.
"""

from dataclasses import dataclass
import itertools
import math

import numpy as np

from cvc_balance.field.influence import CHI2_2DOF_95, Trial, trial_weights_on
from cvc_balance.physics.engine import RotorModel, sample_loads
from cvc_balance.physics.layout import Layout, point_mass

AMPLITUDE_FACTOR = 3.0
"""Measured over predicted coefficients beyond this factor (either way): a mismatch."""
PHASE_LIMIT = math.radians(45.0)
"""Measured against predicted phase beyond this: a mismatch, rad."""
PATTERN_LIMIT = 0.5
"""Share of a plane's measured coefficients that no factor on the prediction explains."""
EXPLAINED = 0.25
"""A mistake explains the coefficients when it leaves under this share unexplained."""
SIGNIFICANT = 0.9999
"""Chi-square level beyond which a pattern unlike the layout's is more than noise."""
IMPLAUSIBLE_TRIAL = 30.0
"""A typed trial unbalance over this many times the rotor's permissible one is no trial."""
CHANNELS = {'force_x': ('force', 0, 'N'), 'force_y': ('force', 1, 'N'),
            'torque_x': ('moment', 0, 'N m'), 'torque_y': ('moment', 1, 'N m')}
"""Channels the layout predicts: a cell's force x, y (and a single support's moment x, y)."""


def plane_positions(layout, planes):
    """
    Return the z (m) of each correction plane named (I, II), from the layout.

    Raises ValueError naming the layout's planes for any other name.
    """
    z = layout.correction_planes()
    known = {} if z is None else {'I': z[0], 'II': z[1]}
    for plane in planes:
        if plane not in known:
            have = ', '.join(f'{p} (z {v:g} m)' for p, v in known.items()) or 'none'
            raise ValueError(f"plane {plane}: the layout '{layout.name}' has correction "
                             f'planes {have}')
    return tuple(known[p] for p in planes)


def predicted_coefficients(layout, sensors, planes, speed):
    """
    Return (coefficients (sensors, planes) complex, known (sensors,) bool) of the layout.

    ``sensors`` channel names (``<support>/force_x`` ...), ``planes`` names (I, II),
    ``speed`` rad/s: each sensor's 1x reading (N or N m) per kg m added in each plane, as
    the engine computes it (steady speed). Channels it cannot predict (another support's,
    an accelerometer, a single support's moments with two supports) are not known: NaN.
    """
    z = plane_positions(layout, planes)
    supports = [s.name for s in layout.supports]
    known = np.array([_channel(name, supports, len(supports)) is not None for name in sensors])
    coefficients = np.full((len(sensors), len(planes)), complex(math.nan, math.nan))
    for j, plane_z in enumerate(z):
        unit = Layout('unit trial', (point_mass('unit', 1.0, 1.0, 0.0, plane_z),),
                      layout.supports, layout.gravity)
        model = RotorModel.from_layout(unit)
        # The loads at steady speed are a constant plus the 1x: four quarter turns give it.
        quarter = [sample_loads(model, k * math.pi / 2.0, speed).supports for k in range(4)]
        for s, name in enumerate(sensors):
            channel = _channel(name, supports, len(supports))
            if channel is None:
                continue
            support, kind, axis = channel
            value = [q[support][0 if kind == 'force' else 1][axis] for q in quarter]
            coefficients[s, j] = complex((value[0] - value[2]) / 2.0,
                                         -(value[1] - value[3]) / 2.0)
    return coefficients, known


def _channel(name, supports, count):
    support, _, component = name.rpartition('/')
    if support not in supports or component not in CHANNELS:
        return None
    kind, axis, _ = CHANNELS[component]
    if kind == 'moment' and count != 1:
        return None
    return support, kind, axis


@dataclass(frozen=True)
class PlaneAgreement:
    """
    One plane's measured coefficients against the layout's.

    ``factor`` measured / predicted (complex, weighted least squares over the sensors)
    with its 95 % radius ``ci95``; ``pattern`` the share of the measured coefficients no
    factor explains; ``agrees``.
    """

    plane: str
    factor: complex
    ci95: float
    pattern: float
    agrees: bool

    def text(self):
        """Return 'plane I: 0.001 times, +0.3 deg'."""
        return (f'plane {self.plane}: {abs(self.factor):.3g} times, '
                f'{int(round(math.degrees(np.angle(self.factor)))):+d} deg')


@dataclass(frozen=True)
class ModelCheck:
    """
    The outcome of :func:`check_coefficients`.

    ``checked`` False when nothing could be compared (``note`` says why); ``sensors``
    those compared; ``predicted`` (all sensors, planes) complex, NaN where not known;
    ``planes`` a :class:`PlaneAgreement` each; ``mismatch``; ``cause`` the likely mistake
    named ('' when none explains it); ``message`` one line for people; ``refusal`` the
    same, saying how to go on anyway.
    """

    checked: bool
    note: str
    sensors: tuple = ()
    predicted: np.ndarray = None
    planes: tuple = ()
    mismatch: bool = False
    cause: str = ''
    message: str = ''

    @property
    def refusal(self):
        """Return the line that refuses the coefficients."""
        return f'{self.message} (--accept-mismatch to go on)'


@dataclass(frozen=True)
class _Case:
    """What a check compares: measured M and predicted P (sensors, planes), weights W."""

    measured: np.ndarray
    predicted: np.ndarray
    weights: np.ndarray
    sensors: tuple
    planes: tuple
    trials: tuple
    keep_trial: bool
    noise_known: bool


def check_coefficients(layout, calibration, speed, trials=(), keep_trial=False,
                       permissible=None):
    """
    Return the :class:`ModelCheck` of a Calibration against a layout's physics.

    ``speed`` rad/s of the readings; ``trials`` the typed :class:`Trial` per run (to name a
    mistake; () for stored coefficients without them); ``permissible`` the rotor's
    permissible unbalance, kg m (judges whether a typed trial is a trial at all).
    """
    try:
        predicted, known = predicted_coefficients(layout, calibration.sensors,
                                                  calibration.planes, speed)
    except ValueError as error:
        return ModelCheck(False, str(error))
    if not known.any():
        return ModelCheck(False, 'no load-cell force among the sensors: the layout predicts '
                          'none of them', predicted=predicted)
    measured = np.asarray(calibration.matrix, complex)[known]
    if calibration.ci95 is not None:
        sigma = np.asarray(calibration.ci95, float)[known] / math.sqrt(CHI2_2DOF_95)
        weights = 1.0 / np.maximum(sigma, 1e-12 * max(float(sigma.max()), 1e-300)) ** 2
    else:
        weights = np.ones(measured.shape)
    compared = tuple(n for n, k in zip(calibration.sensors, known) if k)
    case = _Case(measured, predicted[known], weights, compared, tuple(calibration.planes),
                 tuple(trials), keep_trial, calibration.ci95 is not None)
    planes = tuple(_agreement(case, j) for j in range(len(case.planes)))
    if all(p.agrees for p in planes):
        return ModelCheck(True, '', case.sensors, predicted, planes)
    cause = _explain(case, layout, permissible)
    said = '; '.join(p.text() for p in planes)
    message = (f'the measured influence coefficients disagree with the layout\'s physics '
               f'({said}): ' + (f'likely {cause}' if cause else
                                'no single mistake of the catalogue explains it: check the '
                                'trial masses, radii, angles and planes, and the cells'))
    return ModelCheck(True, '', case.sensors, predicted, planes, True, cause, message)


def _agreement(case, j):
    m = case.measured[:, j]
    p, w = case.predicted[:, j], case.weights[:, j]
    norm = float(np.sum(w * np.abs(p) ** 2))
    if not norm > 0.0:
        return PlaneAgreement(case.planes[j], complex(math.nan), math.inf, 0.0, True)
    factor = complex(np.sum(w * np.conj(p) * m) / norm)
    ci95 = math.sqrt(CHI2_2DOF_95 / norm) if case.noise_known else 0.0
    left = float(np.sum(w * np.abs(m - factor * p) ** 2))
    explained = float(np.sum(w * np.abs(factor * p) ** 2))
    pattern = math.sqrt(left / explained) if explained > 0.0 else math.inf
    off = abs(factor) > AMPLITUDE_FACTOR or abs(factor) < 1.0 / AMPLITUDE_FACTOR \
        or abs(np.angle(factor)) > PHASE_LIMIT
    # Beyond the measurement's own 95 % circle too: noise alone is never a mistake.
    from scipy.stats import chi2      # here: scipy.stats costs every command ~1 s to import
    unlike = pattern > PATTERN_LIMIT and (not case.noise_known
                                          or left > chi2.ppf(SIGNIFICANT, 2 * len(p)))
    agrees = not ((off and abs(factor - 1.0) > ci95) or unlike)
    return PlaneAgreement(case.planes[j], factor, ci95, pattern, agrees)


# -- the catalogue of mistakes -----------------------------------------------------------

def _trial_text(k, trial):
    return (f'trial {k + 1} (plane {trial.plane}, {trial.mass:g} kg at '
            f'{math.degrees(trial.angle):g} deg, r {trial.radius:g} m)')


def _typed_unbalance(trials):
    return max((abs(t.unbalance) for t in trials), default=0.0)


def _changed(trials, k, **fields):
    """Return the trials with trial k's fields replaced (k None: every trial's)."""
    out = []
    for i, t in enumerate(trials):
        if k is None or i == k:
            values = {f: fields[f](t) for f in fields}
            t = Trial(values.get('plane', t.plane), values.get('mass', t.mass),
                      values.get('angle', t.angle), values.get('radius', t.radius))
        out.append(t)
    return tuple(out)


def _trial_mistakes(case, layout, permissible):
    """Yield (text, true trials, keep_trial, conjugate readings, plausible) per mistake."""
    trials = case.trials
    extent = max([layout.correction_radius()] + [s.radius for s in layout.balancing.sites])
    typed = _typed_unbalance(trials)
    implausible = permissible is not None and typed > IMPLAUSIBLE_TRIAL * permissible
    scope = [(k, f'{_trial_text(k, t)}') for k, t in enumerate(trials)]
    if len(trials) > 1:
        scope.append((None, 'every trial'))
    for k, who in scope:
        chosen = trials if k is None else (trials[k],)
        radius = max(t.radius for t in chosen)
        yield (f'the trial mass in g typed as kg (x1000): {who}; give the mass in kg',
               _changed(trials, k, mass=lambda t: t.mass / 1000.0), case.keep_trial, False,
               radius <= 2.0 * extent and (implausible or permissible is None))
        yield (f'the trial radius in mm typed as m (x1000): {who}; give the radius in m',
               _changed(trials, k, radius=lambda t: t.radius / 1000.0), case.keep_trial,
               False, radius > 2.0 * extent)
        yield (f'the trial radius in cm typed as m (x100): {who}; give the radius in m',
               _changed(trials, k, radius=lambda t: t.radius / 100.0), case.keep_trial,
               False, radius > 2.0 * extent)
        if any(math.sin(t.angle) ** 2 > 1e-6 for t in chosen):
            yield (f'the trial angle measured in the opposite sense (mirrored about the '
                   f'zero mark): {who}; angles count from rotor X toward rotor Y',
                   _changed(trials, k, angle=lambda t: -t.angle), case.keep_trial, False,
                   True)
        if any(abs(t.angle) > 1e-9 for t in chosen):
            yield (f'the trial angle typed in radians where degrees are read: {who}',
                   _changed(trials, k, angle=lambda t: math.degrees(t.angle)),
                   case.keep_trial, False, True)
        if k is not None:
            for plane in case.planes:
                if plane != trials[k].plane:
                    yield (f'{who} was bolted in plane {plane}, not plane {trials[k].plane}',
                           _changed(trials, k, plane=lambda t, p=plane: p), case.keep_trial,
                           False, True)
            yield (f'{who} shows no trial weight: was it on for its run?',
                   _changed(trials, k, mass=lambda t: 0.0), case.keep_trial, False, True)
    if len(case.planes) > 1:
        for order in itertools.permutations(case.planes):
            if order == case.planes:
                continue
            swap = dict(zip(case.planes, order))
            pairs = ' and '.join(f'{a} with {b}' for a, b in swap.items() if a < b)
            yield (f'the planes swapped ({pairs}): each trial was in the other plane',
                   _changed(trials, None, plane=lambda t: swap.get(t.plane, t.plane)),
                   case.keep_trial, False, True)
    for order in itertools.islice(itertools.permutations(range(len(trials))), 1, 24):
        yield ('the trial runs given in another order than their --trial weights (runs in '
               f'the order of trials {", ".join(str(i + 1) for i in order)})',
               tuple(trials[i] for i in order), case.keep_trial, False, True)
    if len(trials) > 1:
        yield (('each trial was taken off before the next run (leave out --keep-trial)'
                if case.keep_trial else 'the trial weights stayed on for the runs after '
                'them (give --keep-trial)'), trials, not case.keep_trial, False, True)
    yield ('the readings\' phase in the opposite sense to the weights\' angles (phase lag '
           'for lead)', trials, case.keep_trial, True, True)


def _sensor_mistakes(case, supports):
    """Yield (text, transform of predicted rows (S, S), plausible) per cell mistake."""
    sensors = case.sensors
    rows = {name: s for s, name in enumerate(sensors)}

    def matrix(mapping, scale=None):
        out = np.zeros((len(sensors), len(sensors)), complex)
        for s, name in enumerate(sensors):
            source = mapping.get(name, name)
            if source in rows:
                out[s, rows[source]] = (scale or {}).get(name, 1.0)
        return out

    names = [s.name for s in supports]
    for a, b in itertools.combinations(names, 2):
        mapping = {}
        for name in sensors:
            support, _, component = name.rpartition('/')
            if support in (a, b):
                mapping[name] = f'{b if support == a else a}/{component}'
        yield f'the cells of supports {a} and {b} swapped (each reads the other\'s bearing)', \
            matrix(mapping), True
    for support in names:
        own = [n for n in sensors if n.rpartition('/')[0] == support]
        if not own:
            continue
        yield (f'the cell of support {support} reading with its sign reversed (mounted the '
               'other way up)', matrix({}, {n: -1.0 for n in own}), True)
        yield (f'the cell of support {support} reading kN where N are read (x1000)',
               matrix({}, {n: 1e-3 for n in own}), True)
        swapped = {f'{support}/force_x': f'{support}/force_y',
                   f'{support}/force_y': f'{support}/force_x'}
        yield (f'the x and y axes of the cell of support {support} swapped', matrix(swapped),
               True)
    if len(names) > 1:
        yield ('every cell reading kN where N are read (x1000)',
               matrix({}, {n: 1e-3 for n in sensors}), True)


def _explain(case, layout, permissible):
    """Return the text of the mistake that best explains the measured coefficients, or ''."""
    w, m = case.weights, case.measured
    energy = float(np.sum(w * np.abs(m) ** 2))
    if not energy > 0.0:
        return ''

    def misfit(alpha):
        return float(np.sum(w * np.abs(m - alpha) ** 2)) / energy

    candidates = []
    if case.trials and len(case.trials) >= len(case.planes):
        typed = trial_weights_on(case.trials, case.planes, case.keep_trial)
        inverse = np.linalg.pinv(typed)
        typed_implausible = permissible is not None and \
            _typed_unbalance(case.trials) > IMPLAUSIBLE_TRIAL * permissible
        mistakes = _trial_mistakes(case, layout, permissible)
        for text, true, keep, conjugate, plausible in mistakes:
            change = trial_weights_on(true, case.planes, keep) @ case.predicted.T
            if conjugate:          # readings typed as the conjugates of the true ones
                change = np.conj(change)
            alpha = (inverse @ change).T
            candidates.append((misfit(alpha), not plausible, text))
    else:
        typed_implausible = False
    for text, transform, plausible in _sensor_mistakes(case, layout.supports):
        scaled = 'kN' in text
        candidates.append((misfit(transform @ case.predicted),
                           not plausible or (scaled and typed_implausible), text))
    candidates += [(misfit(alpha), False, text) for alpha, text in _offsets(case)]
    if not candidates:
        return ''
    best = min(c[0] for c in candidates)
    if best > EXPLAINED or best > 0.5 * misfit(case.predicted):
        return ''
    # Named mistakes before fitted offsets (which have a parameter to fit the noise with).
    # Plausible before not; named mistakes before the catch-alls (a fitted offset, a trial
    # not on), which explain much with little said; then the best fit.
    near = sorted((c for c in candidates if c[0] <= 1.5 * best + 0.01),
                  key=lambda c: (c[1], _catch_all(c[2]), c[0]))
    first = near[0]
    named = list(dict.fromkeys(c[2] for c in near if c[1] == first[1]
                               and _catch_all(c[2]) == _catch_all(first[2])))[:3]
    return ', or as well: '.join(named)


def _catch_all(text):
    return 'deg off' in text or 'no trial weight' in text


def _offsets(case):
    """Yield (coefficients, text) of angles offset: every trial's alike, or one trial's."""
    w, m, p = case.weights, case.measured, case.predicted
    overall = complex(np.sum(w * np.conj(p) * m))
    if abs(overall) > 0.0 and abs(np.angle(overall)) > math.radians(10.0):
        turn = overall / abs(overall)
        yield turn * p, (f'every angle counted from another zero mark '
                         f'({int(round(math.degrees(np.angle(turn)))):+d} deg off)')
    if not case.trials or len(case.trials) < len(case.planes):
        return
    typed = trial_weights_on(case.trials, case.planes, case.keep_trial)
    inverse = np.linalg.pinv(typed)
    change = typed @ p.T                          # runs x sensors, as typed
    for k, trial in enumerate(case.trials):
        # Trial k's weight at angle + d: its own run's change turns by e^{id}.
        alone = trial_weights_on(case.trials[k:k + 1], case.planes) @ p.T
        runs = [k] + ([r for r in range(k + 1, len(case.trials))] if case.keep_trial else [])
        measured_change = (typed @ m.T)
        d = complex(np.sum(np.conj(alone) * (measured_change[k] - change[k] + alone)))
        if abs(d) == 0.0 or abs(np.angle(d)) < math.radians(10.0):
            continue
        turn = d / abs(d)
        shifted = change.copy()
        for r in runs:
            shifted[r] = shifted[r] + (turn - 1.0) * alone[0]
        yield ((inverse @ shifted).T,
               f'{_trial_text(k, trial)} at another angle than typed '
               f'({int(round(math.degrees(np.angle(turn)))):+d} deg off: another hole, or '
               'another zero mark)')
