"""
What a recorded run was in a field-balancing visit: its label, written into the bag.

A service visit records a baseline run, one trial run per trial weight, a check run after
the correction and, on later visits, trim runs. ``cvc-balance record --run KIND`` (and
``simulate --run KIND``) writes the kind into the bag, with the trial weight of a trial
run (``--trial PLANE:MASS_KG@ANGLE_DEG,RADIUS_M``), as custom data beside the machine's
id (:mod:`cvc_balance.bag.machine`: keys ``run`` and ``trial``). ``calibrate`` then takes
each trial's weight from its bag, refuses a baseline given as a trial (and the reverse)
and a typed ``--trial`` that differs from the one recorded; ``info`` prints the label.

The trial is kept as text in the field notation (:mod:`cvc_balance.field.notation`), kg,
degrees from the rotor's X axis and m, written back from the parsed values so that every
reader gets the same numbers.
"""

from dataclasses import dataclass
import math

from cvc_balance.field.notation import bag_trial

RUN, TRIAL = 'run', 'trial'
"""The custom-data keys of the label."""
KINDS = ('baseline', 'trial', 'check', 'trim')
"""The kinds of run of a field-balancing visit."""


@dataclass(frozen=True)
class RunLabel:
    """A run's kind (one of KINDS) and, for a trial run, its trial weight (field Trial)."""

    kind: str
    trial: object = None

    @property
    def trial_text(self):
        """Return the trial weight as ``PLANE:MASS_KG@ANGLE_DEG,RADIUS_M`` (None: none)."""
        if self.trial is None:
            return None
        t = self.trial
        return f'{t.plane}:{t.mass!r}@{math.degrees(t.angle)!r},{t.radius!r}'

    def describe(self):
        """Return the label for people: ``trial run: plane I, 0.2 kg at 0 deg, r 0.68 m``."""
        if self.trial is None:
            return f'{self.kind} run'
        t = self.trial
        degrees = math.degrees(t.angle) % 360.0
        return (f'{self.kind} run: plane {t.plane}, {t.mass:.4g} kg at {degrees:.4g} deg, '
                f'r {t.radius:.4g} m')

    def custom_data(self):
        """Return the label's custom data {key: text}."""
        data = {RUN: self.kind}
        if self.trial is not None:
            data[TRIAL] = self.trial_text
        return data

    def mapping(self):
        """Return the label as plain data (JSON): kind and trial text (or null)."""
        return {'kind': self.kind, 'trial': self.trial_text}


def run_label(kind, trial_text=None):
    """
    Return the RunLabel of a kind and a trial's text; ValueError names what is wrong.

    A trial run needs its trial weight; any other run has none.
    """
    if kind not in KINDS:
        raise ValueError(f'--run: give one of {", ".join(KINDS)}, got {kind!r}')
    if kind == 'trial' and trial_text is None:
        raise ValueError('--run trial: give the trial weight too (--trial '
                         'PLANE:MASS_KG@ANGLE_DEG,RADIUS_M, e.g. I:0.2@0,0.68)')
    if kind != 'trial' and trial_text is not None:
        raise ValueError(f'--trial goes with --run trial only (this run is a {kind} run)')
    return RunLabel(kind, None if trial_text is None else bag_trial(trial_text))


def label_of(custom_data):
    """
    Return (RunLabel or None, problem text or None) of a bag's custom data.

    A bag without a label gives (None, None); a label no release wrote (an unknown kind, a
    trial that does not parse) gives (None, why), so that a reader says it and goes on
    without it.
    """
    kind = custom_data.get(RUN)
    if kind is None:
        return None, None
    try:
        return run_label(kind, custom_data.get(TRIAL)), None
    except ValueError as error:
        return None, f'the run label in the bag is not usable: {error}'


def labels_of(paths):
    """Return each bag's RunLabel (None: unlabelled or unusable) of ``paths``."""
    from cvc_balance.bag.machine import bag_custom_data
    return [label_of(bag_custom_data(path))[0] for path in paths]


def calibration_trials(paths, typed):
    """
    Return the trial weight of each trial run of a calibration: ``paths`` baseline first.

    ``typed``: the field Trials given by hand (``--trial``, in order; empty: none). Each
    labelled trial run gives its own; a typed one must equal it. ValueError, naming the
    bag, for a run recorded as another kind (a baseline among the trials, a trial as the
    baseline: runs swapped), a typed weight that differs from the one recorded, or a trial
    run with neither.
    """
    labels = labels_of(paths)
    baseline, trials = labels[0], labels[1:]
    if baseline is not None and baseline.kind != 'baseline':
        raise ValueError(f'{paths[0]} was recorded as a {baseline.kind} run, not the baseline: '
                         'give the baseline run first, then the trial runs')
    if typed and len(typed) != len(trials):
        raise ValueError(f'{len(typed)} --trial given for {len(trials)} trial runs: give one '
                         'per trial run, in order, or none to use the weights recorded')
    chosen = []
    for k, (path, label) in enumerate(zip(paths[1:], trials)):
        if label is not None and label.kind != 'trial':
            raise ValueError(f'{path} was recorded as a {label.kind} run, not a trial run: '
                             'give the baseline run first, then the trial runs')
        if typed:
            if label is not None and not _same_trial(typed[k], label.trial):
                said = RunLabel('trial', typed[k]).trial_text
                raise ValueError(f'--trial {said} differs from the trial weight {path} was '
                                 f'recorded with ({label.trial_text}): leave --trial out to '
                                 'use the recorded ones')
            chosen.append(typed[k])
        elif label is None:
            raise ValueError(f'{path} carries no trial weight (recorded without --run trial '
                             '--trial ...): give --trial PLANE:MASS_KG@ANGLE_DEG,RADIUS_M '
                             'for every trial run')
        else:
            chosen.append(label.trial)
    return chosen


def _same_trial(a, b):
    """Whether two trial weights are one (the plane, and mass, angle, radius to 1e-9)."""
    turn = math.remainder(a.angle - b.angle, 2.0 * math.pi)
    return a.plane == b.plane and abs(turn) <= 1e-9 and \
        math.isclose(a.mass, b.mass, rel_tol=1e-9) and \
        math.isclose(a.radius, b.radius, rel_tol=1e-9)
