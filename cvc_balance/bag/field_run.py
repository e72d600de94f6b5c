"""
Field balancing on recorded runs: each run's 1x readings, the coefficients, the correction.

A run is a bag with the encoder (``joint_states``, or ``speed``) and measured channels:
each support's load cell (``supports/<name>/measured_load``, WrenchStamped, stator frame:
channels ``<name>/force_x`` ... ``<name>/torque_z``, header stamps) and any
std_msgs/Float64 topic but ``speed`` (an accelerometer, a vibration meter: channel named by
its topic, log times). The motion passes the node's input checks; the longest stretch at
steady speed, cut to whole revolutions, gives each channel's 1x phasor
(:mod:`cvc_balance.field.order_tracking`). Default channels: the cells' force x and y
(and their tilting moment x and y with a single support) and every Float64 channel.

:func:`calibrate_runs` makes influence coefficients from a baseline run and trial runs;
:func:`correct_run` the corrections of a run, from coefficients or, without them, from
the unbalance its load cells identify (:mod:`cvc_balance.bag.identify_run`), with the
weights at the layout's sites and the ISO 21940-11 grade before and after.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from cvc_balance.bag.identify_run import identify_bag
from cvc_balance.bag.mcap_reader import BagError, float64_samples, wrench_samples
from cvc_balance.bag.replay import layout_events, read_inputs
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.field import (calibrate, continuous_correction, continuous_plan,
                               optimal_plan, problem_from_readings, problem_from_unbalance,
                               split_plan, steady_window, track)
from cvc_balance.field.correction import with_unbalance_limits
from cvc_balance.field.influence import CHI2_2DOF_95
from cvc_balance.field.order_tracking import DEFAULT_TOLERANCE
from cvc_balance.messages import topics
from cvc_balance.physics import iso21940
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.motion import accepted_samples, MAX_STAMP_JUMP

COMPONENTS = ('force_x', 'force_y', 'force_z', 'torque_x', 'torque_y', 'torque_z')
SPEED_MISMATCH = 0.02
"""Runs whose steady speeds differ by more than 2 % are compared with a warning."""


@dataclass
class RunReadings:
    """
    One run's 1x readings: ``phasors`` {channel: Phasor} and ``units`` {channel: unit}.

    ``window`` the steady stretch (stamps, s) read and ``log_window`` the same in log
    times; ``layout`` in force there (None if the bag has none and none was given);
    ``first_ns`` the bag's first motion log time (its date); ``problems`` what the reader
    had to skip.
    """

    bag: str
    window: object
    log_window: object
    phasors: dict
    units: dict
    layout: object
    first_ns: int
    problems: list = field(default_factory=list)


def channel_sources(bag):
    """Return {channel name: (bag channel, component index or None, unit)} of a bag."""
    sources = {}
    for channel in sorted(bag.channels.values(), key=lambda c: c.topic):
        parts = channel.topic.strip('/').split('/')
        if channel.msg_type == topics.WRENCH_TYPE and len(parts) >= 3 \
                and parts[-3:-2] == ['supports'] and parts[-1] == 'measured_load':
            for k, component in enumerate(COMPONENTS):
                unit = 'N' if component.startswith('force') else 'N m'
                sources[f'{parts[-2]}/{component}'] = (channel, k, unit)
        elif channel.msg_type == topics.FLOAT64_TYPE and parts[-1] != topics.SPEED:
            sources['/'.join(parts)] = (channel, None, 'as recorded')
    return sources


def default_sensors(sources, layout):
    """Return the channels read when none are named (see the module's description)."""
    single = layout is not None and len(layout.supports) == 1
    wanted = ('force_x', 'force_y') + (('torque_x', 'torque_y') if single else ())
    return [name for name, (_, index, _) in sources.items()
            if index is None or name.split('/')[-1] in wanted]


def read_run(bag_path, sensors=None, speed=None, tolerance=DEFAULT_TOLERANCE,
             joint_name='gantry_joint', layout_file=None, max_speed=1000.0):
    """
    Return the :class:`RunReadings` of a bag (see the module's description).

    ``sensors``: channel names to read (default: :func:`default_sensors`); ``speed``
    rad/s: read the steady stretch at that speed (default: the speed the run spent most
    time at). Raises ValueError (BagError) naming what is missing.
    """
    bag = open_bag(bag_path)
    motion, layout_messages = read_inputs(bag, joint_name)
    stamp, log = motion.stamp * 1e-9, motion.log_time * 1e-9
    accepted = accepted_samples(stamp, motion.angle, motion.omega, max_speed, MAX_STAMP_JUMP,
                                receive=log)
    stamp, log = stamp[accepted], log[accepted]
    angle, omega = np.unwrap(motion.angle[accepted]), motion.omega[accepted]
    if len(stamp) < 2:
        raise BagError(f'{bag.path}: fewer than two usable motion samples')
    try:
        window = steady_window(stamp, angle, omega, speed, tolerance)
    except ValueError as error:
        raise BagError(f'{bag.path}: {error}') from None
    layout, problems = None, list(bag.problems)
    try:
        events, layout_problems = layout_events(bag, layout_messages, layout_file)
        problems += layout_problems
        start_log = np.interp(window.start, stamp, log) * 1e9
        layout = [lay for at, lay in events if at <= start_log][-1:] or [events[0][1]]
        layout = layout[0]
    except BagError:
        if layout_file is not None:
            raise
    sources = channel_sources(bag)
    names = default_sensors(sources, layout) if sensors is None else list(sensors)
    missing = [n for n in names if n not in sources]
    if missing or not names:
        found = ', '.join(sources) or 'none'
        raise BagError(f'{bag.path}: no channel {", ".join(missing) or "to read"} (channels: '
                       f'{found}; load cells are supports/<name>/measured_load, other '
                       'channels std_msgs/Float64 topics)')
    log_window = type(window)(float(np.interp(window.start, stamp, log)),
                              float(np.interp(window.end, stamp, log)), window.speed,
                              window.revolutions, window.spread)
    phasors, units, cache = {}, {}, {}
    for name in names:
        channel, index, unit = sources[name]
        if channel.id not in cache:
            cache[channel.id] = wrench_samples(bag, channel) if index is not None \
                else float64_samples(bag, channel)
        if index is not None:
            stamps, force, torque = cache[channel.id]
            values = np.concatenate([force, torque], axis=1)[:, index]
            times, motion_time, used = stamps * 1e-9, stamp, window
        else:
            log_times, values = cache[channel.id]
            times, motion_time, used = log_times * 1e-9, log, log_window
        try:
            phasors[name] = track(times, values, motion_time, angle, used)
        except ValueError as error:
            raise BagError(f'{bag.path}: channel {name}: {error}') from None
        units[name] = unit
    return RunReadings(str(bag_path), window, log_window, phasors, units, layout,
                       int(motion.log_time.min()), problems)


def calibrate_runs(baseline_path, trial_paths, trials, keep_trial=False, sensors=None,
                   speed=None, tolerance=DEFAULT_TOLERANCE, joint_name='gantry_joint'):
    """
    Return (Calibration, [RunReadings], warnings) of a baseline run and trial runs.

    ``trials``: one :class:`~cvc_balance.field.influence.Trial` (kg, rad, m) per trial
    run, in order. Every run is read at the baseline's steady speed (or ``speed``).
    """
    if len(trial_paths) != len(trials):
        raise ValueError(f'{len(trial_paths)} trial runs but {len(trials)} --trial weights: '
                         'give one --trial per trial run, in order')
    baseline = read_run(baseline_path, sensors, speed, tolerance, joint_name)
    names = list(baseline.phasors)
    at = baseline.window.speed if speed is None else speed
    runs = [baseline] + [read_run(p, names, at, tolerance, joint_name) for p in trial_paths]
    warnings = []
    for k, run in enumerate(runs[1:]):
        off = abs(run.window.speed / baseline.window.speed - 1.0)
        if off > SPEED_MISMATCH:
            warnings.append(f'trial run {k + 1} ({run.bag}) is at {run.window.speed:.4g} '
                            f'rad/s, {off:.1%} off the baseline\'s {baseline.window.speed:.4g}: '
                            'readings grow with speed (forces as its square)')
    calibration = calibrate(
        [baseline.phasors[n].value for n in names], trials,
        [[run.phasors[n].value for n in names] for run in runs[1:]], names, keep_trial,
        [baseline.phasors[n].sigma for n in names],
        [[run.phasors[n].sigma for n in names] for run in runs[1:]])
    return calibration, runs, warnings


@dataclass
class GradeView:
    """
    The rotor's balance per correction plane against its ISO 21940-11 grade.

    ``planes`` names ('I', 'II'); ``z`` m; ``before`` complex kg m (identified) with its
    95 % radius ``ci95``; ``permissible`` kg m per plane; ``grade`` G mm/s at ``speed``
    rad/s; ``mass`` kg and ``shares`` (ISO allocation) to turn amounts into a grade.
    """

    planes: tuple
    z: tuple
    before: np.ndarray
    ci95: tuple
    permissible: np.ndarray
    grade: float
    speed: float
    mass: float
    shares: tuple

    def equivalent_grade(self, unbalance):
        """Return the G (mm/s) that per-plane unbalances (complex kg m) achieve."""
        return iso21940.equivalent_grade(np.abs(unbalance), self.shares, self.mass,
                                         self.speed)

    def after(self, plan, planes):
        """
        Return the per-plane unbalance (complex kg m) after a plan's corrections.

        ``planes`` names the plan's corrections (kg m); planes not here add nothing.
        """
        added = np.zeros(len(self.planes), complex)
        for name, value in zip(planes, plan.corrections):
            if name in self.planes:
                added[self.planes.index(name)] += value
        return self.before + added


@dataclass
class FieldCorrection:
    """
    A run's corrections: the ``problem``, its ``plans`` (continuous, split, optimal).

    ``method`` 'influence coefficients' or 'identified unbalance'; ``sites`` {plane:
    WeightSites}; ``radius`` {plane: m} at which continuous corrections are given as
    masses; ``grade`` a :class:`GradeView` or None (no load cells or layout);
    ``warnings`` one line each; ``objective`` and ``max_weights`` of the optimal plan.
    """

    run: RunReadings
    method: str
    problem: object
    plans: list
    sites: dict
    radius: dict
    grade: object
    warnings: list
    objective: str = 'residual'
    max_weights: int = None


def grade_view(run, layout_file=None, joint_name='gantry_joint'):
    """
    Return the :class:`GradeView` of a run (RunReadings) from its load cells, or None.

    None when the bag has no load cells or no layout with two correction planes. The
    segment identified is the layout's in force over the run's steady window; the grade
    is judged at the layout's service speed (default: the run's steady speed).
    """
    if run.layout is None or run.layout.correction_planes() is None:
        return None
    segments, _ = identify_bag(run.bag, layout_file, joint_name)
    middle = 0.5e9 * (run.log_window.start + run.log_window.end)
    usable = [s for s in segments if s.readings and s.estimate.identifiable]
    usable = [s for s in usable if s.start_ns <= middle <= s.end_ns] or usable
    if not usable:
        return None
    segment = usable[-1]
    layout = segment.layout
    model = RotorModel.from_layout(layout)
    z = layout.correction_planes()
    planes = segment.identified.planes
    speed = layout.balancing.service_speed or run.window.speed
    shares = iso21940.plane_shares(model.s_z / model.mass, *z)
    u_per = iso21940.permissible_unbalance(layout.balancing.grade, model.mass, speed)
    return GradeView(('I', 'II'), tuple(z), np.array([v.value for _, v in planes]),
                     tuple(v.ci95 for _, v in planes), np.array([u_per * s for s in shares]),
                     layout.balancing.grade, speed, model.mass, shares)


def correct_run(run_path, calibration=None, record=None, layout_file=None,
                objective=None, limit=None, max_weights=None, tolerance=DEFAULT_TOLERANCE,
                joint_name='gantry_joint', time_limit=30.0):
    """
    Return the :class:`FieldCorrection` of a run (see the module's description).

    With ``calibration`` (and its ``record``: speed, units) the run's readings of the
    calibrated sensors are corrected (``limit``: largest residual reading allowed);
    without, the unbalance its load cells identify is, against the layout's grade. Limits
    keep the readings' (or the identification's) 95 % radius to spare. ``objective``
    'fewest' (default when there are limits) or 'residual' (at most ``max_weights``
    weights, default two per plane with sites). Sites and the grade come from
    ``layout_file`` or the bag's layout.
    """
    warnings = []
    speed = None if record is None else record.get('speed')
    sensors = None if calibration is None else list(calibration.sensors)
    run = read_run(run_path, sensors, speed, tolerance, joint_name, layout_file)
    layout = run.layout
    sites = {s.plane: s for s in layout.balancing.sites} if layout is not None else {}
    grade = grade_view(run, layout_file, joint_name)
    if calibration is not None:
        names = list(calibration.sensors)
        sigma = np.array([run.phasors[n].sigma for n in names])
        # Each channel counts by its own noise: newtons and m/s^2 add up.
        weights = 1.0 / np.maximum(sigma, 1e-12 * max(float(sigma.max()), 1e-300))
        weights /= weights.mean()
        limits = None
        if limit is not None:
            limits = float(limit) - math.sqrt(CHI2_2DOF_95) * sigma
            if not np.all(limits > 0.0):
                raise ValueError(f'--limit {limit:g} is within the readings\' own 95 % '
                                 f'uncertainty ({math.sqrt(CHI2_2DOF_95) * sigma.max():.3g}): '
                                 'no plan can be shown to meet it')
        problem = problem_from_readings(calibration, [run.phasors[n].value for n in names],
                                        weights, limits,
                                        record.get('correction_unit', 'kg m') if record
                                        else 'kg m')
        if grade is not None and problem.unit == 'kg m':
            # The grade limits the plan too: the identified unbalance plus the weights.
            problem = with_unbalance_limits(problem, grade.planes, grade.before,
                                            grade.permissible - np.asarray(grade.ci95))
        method = 'influence coefficients'
        warnings += list(calibration.warnings)
    else:
        if grade is None:
            raise BagError(f'{run_path}: no load cells to identify the unbalance from (topics '
                           'supports/<name>/measured_load) or no layout with two correction '
                           'planes: give --coefficients from trial runs')
        problem = problem_from_unbalance(grade.planes, grade.before,
                                         grade.permissible - np.asarray(grade.ci95))
        if not np.all(problem.limits > 0.0):
            raise ValueError('the identified unbalance is uncertain by more than the grade '
                             'allows (95 % radius over U_per): record a longer run')
        method = 'identified unbalance'
    radius = {}
    for plane in problem.planes:
        if plane in sites:
            radius[plane] = sites[plane].radius
        elif layout is not None and layout.correction_radius() > 0.0:
            radius[plane] = layout.correction_radius()
        else:
            radius[plane] = None
    unknown = [p for p in sites if p not in problem.planes]
    if unknown:
        warnings.append(f'the layout has weight sites for plane {", ".join(unknown)}, which '
                        'the coefficients do not name: those sites are not used')
    used_sites = {p: s for p, s in sites.items() if p in problem.planes}
    if objective is None:
        objective = 'fewest' if problem.limits is not None else 'residual'
    if objective == 'fewest' and problem.limits is None:
        raise ValueError('--objective fewest with coefficients needs --limit (the largest '
                         'residual reading allowed, in the sensors\' units); or leave out '
                         '--coefficients to plan on the identified unbalance against the grade')
    if max_weights is None and objective == 'residual':
        max_weights = 2 * len(used_sites)
    continuous = continuous_correction(problem)
    plans = [continuous_plan(problem, continuous)]
    if used_sites:
        plans.append(split_plan(problem, used_sites, continuous))
        plans.append(optimal_plan(problem, used_sites, objective, max_weights,
                                  time_limit=time_limit))
    return FieldCorrection(run, method, problem, plans, used_sites, radius, grade, warnings,
                           objective, max_weights)
