"""
Field balancing on recorded runs: each run's 1x readings, the coefficients, the correction.

A run is a bag with the rotor's angle (the encoder's ``joint_states``, or ``speed``, or a
once-per-revolution tach: ``names.keyphasor``, :mod:`cvc_balance.bag.channels`) and
measured channels: each support's load cell (``supports/<name>/measured_load``,
WrenchStamped, stator frame: channels ``<name>/force_x`` ... ``<name>/torque_z``, header
stamps) and the vibration channels of :func:`cvc_balance.bag.channels.vibration_channels`
(std_msgs/Float64 topics at their log times, Vector3Stamped and Imu axes at their header
stamps; never the motion's own topics: the keyphasor, speed). The motion passes the node's
input checks; the longest stretch at
steady speed, cut to whole revolutions, gives each channel's 1x phasor
(:mod:`cvc_balance.field.order_tracking`). Default channels: the cells' force x and y
(and their tilting moment x and y with a single support) and every vibration channel.

:func:`calibrate_runs` makes influence coefficients from a baseline run and trial runs;
:func:`correct_run` the corrections of a run, from coefficients or, without them, from
the unbalance its load cells identify (:mod:`cvc_balance.bag.identify_run`), with the
weights at the layout's sites and the ISO 21940-11 grade before and after.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from cvc_balance.bag.channels import channel_samples, vibration_channels
from cvc_balance.bag.identify_run import cell_readings
from cvc_balance.bag.inputs import input_channels, InputTopics
from cvc_balance.bag.mcap_reader import BagError, wrench_samples
from cvc_balance.bag.replay import layout_events, read_inputs
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.field import (calibrate, continuous_correction, continuous_plan,
                               optimal_plan, problem_from_readings, problem_from_unbalance,
                               split_plan, steady_stretches, track)
from cvc_balance.field.correction import with_unbalance_limits
from cvc_balance.field.holes import site_of_hole
from cvc_balance.field.coefficients import at_speed, record_trials
from cvc_balance.field.influence import CHI2_2DOF_95
from cvc_balance.field.model_check import (check_coefficients, ModelCheck, plane_positions,
                                           predicted_coefficients)
from cvc_balance.field.order_tracking import busiest_speed, DEFAULT_TOLERANCE
from cvc_balance.field.plan import PlacedWeight
from cvc_balance.field.trial_weight import advise
from cvc_balance.identify import CellReadings, fit, identified_unbalance, Motion
from cvc_balance.messages import topics
from cvc_balance.physics import iso21940
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.motion import accepted_motion, accepted_samples, MAX_STAMP_JUMP

COMPONENTS = ('force_x', 'force_y', 'force_z', 'torque_x', 'torque_y', 'torque_z')
SPEED_MISMATCH = 0.02
"""Runs whose steady speeds differ by more than 2 % are compared with a warning."""


@dataclass(frozen=True)
class Segment:
    """
    One layout segment of a run: the motion under one layout, and its steady stretches.

    ``number`` counts from 1 over the segments with motion, as ``identify`` numbers them;
    ``layout`` in force (None without one); ``start``/``end`` the log times (s) of its
    first and last motion samples; ``stretches`` its :class:`SteadyWindow` (stamps, s) at
    the speed read, in order; ``note`` why there is none.
    """

    number: int
    layout: object
    start: float
    end: float
    stretches: tuple
    note: str = ''
    first_ns: int = 0

    @property
    def longest(self):
        """Return the stretch with the most whole revolutions (the later of equals), or None."""
        if not self.stretches:
            return None
        return max(reversed(self.stretches), key=lambda w: w.revolutions)


@dataclass
class RunReadings:
    """
    One run's 1x readings: ``phasors`` {channel: Phasor} and ``units`` {channel: unit}.

    ``window`` the steady stretch (stamps, s) read and ``log_window`` the same in log
    times; ``layout`` in force there (None if the bag has none and none was given);
    ``first_ns`` the bag's first motion log time (its date); ``problems`` what the reader
    had to skip; ``segment`` the number of the layout segment read, ``segments`` every
    :class:`Segment` of the run (a run is never read across a layout change);
    ``names`` the input topics read (:class:`~cvc_balance.bag.inputs.InputTopics`) and
    ``angle_from`` {kind: 'encoder' | 'speed' | 'keyphasor', topic}: where the angle came from.
    """

    bag: str
    window: object
    log_window: object
    phasors: dict
    units: dict
    layout: object
    first_ns: int
    problems: list = field(default_factory=list)
    segment: int = 1
    segments: tuple = ()
    names: object = None
    angle_from: dict = None

    @property
    def chosen(self):
        """Return the :class:`Segment` read."""
        return self.segments[self.segment - 1]


def channel_sources(bag, motion_topics=()):
    """
    Return {channel name: (bag channel, component index or ChannelSource, unit)} of a bag.

    Load-cell components (index 0-5) and vibration channels (their
    :class:`~cvc_balance.bag.channels.ChannelSource`); ``motion_topics``: the topics the
    motion is read from (a keyphasor, a speed), never a vibration channel.
    """
    sources = {}
    for channel in sorted(bag.channels.values(), key=lambda c: c.topic):
        parts = channel.topic.strip('/').split('/')
        if channel.msg_type == topics.WRENCH_TYPE and len(parts) >= 3 \
                and parts[-3:-2] == ['supports'] and parts[-1] == 'measured_load':
            for k, component in enumerate(COMPONENTS):
                unit = 'N' if component.startswith('force') else 'N m'
                sources[f'{parts[-2]}/{component}'] = (channel, k, unit)
    for source in vibration_channels(bag, exclude=motion_topics):
        sources[source.name] = (source.channel, source, source.unit)
    return sources


def default_sensors(sources, layout):
    """Return the channels read when none are named (see the module's description)."""
    single = layout is not None and len(layout.supports) == 1
    wanted = ('force_x', 'force_y') + (('torque_x', 'torque_y') if single else ())
    return [name for name, (_, index, _) in sources.items()
            if not isinstance(index, int) or name.split('/')[-1] in wanted]


@dataclass
class _Motion:
    """A run's accepted motion: stamps and log times (s), angle (rad, unwrapped), omega."""

    stamp: np.ndarray
    log: np.ndarray
    angle: np.ndarray
    omega: np.ndarray


def run_segments(bag, joint_name='gantry_joint', layout_file=None, speed=None,
                 tolerance=DEFAULT_TOLERANCE, max_speed=1000.0, segment=None, names=None):
    """
    Return (motion, [Segment], problems) of an open bag: its layout segments.

    The segments are the bag's own layout messages' (a ``layout_file`` replaces the
    layout of each, never joins them); each segment's steady stretches are at ``speed``
    rad/s, or at the speed the run spent most time at (the chosen ``segment``'s, when a
    number is given). A bag without layouts is one segment with layout None. ``names``:
    the input topics (:class:`~cvc_balance.bag.inputs.InputTopics`: a keyphasor instead of
    the encoder), as replay takes them.
    """
    motion, layout_messages = read_inputs(bag, joint_name, names)
    stamp, log = motion.stamp * 1e-9, motion.log_time * 1e-9
    accepted = accepted_samples(stamp, motion.angle, motion.omega, max_speed, MAX_STAMP_JUMP,
                                receive=log)
    kept = _Motion(stamp[accepted], log[accepted], np.unwrap(motion.angle[accepted]),
                   motion.omega[accepted])
    if len(kept.stamp) < 2:
        raise BagError(f'{bag.path}: fewer than two usable motion samples')
    problems = list(bag.problems)
    try:
        events, layout_problems = layout_events(bag, layout_messages)
        problems += layout_problems
    except BagError:
        events = [(np.iinfo(np.int64).min, None)]
    if layout_file is not None:
        from cvc_balance.physics.layout_file import load_layout
        replaced = load_layout(layout_file)
        events = [(at, replaced) for at, _ in events]
    bounds = [at for at, _ in events[1:]] + [np.iinfo(np.int64).max]
    log_ns = motion.log_time[accepted]
    spans = []
    for (start_ns, layout), end_ns in zip(events, bounds):
        lo, hi = (int(k) for k in np.searchsorted(log_ns, [start_ns, end_ns]))
        if hi - lo >= 2:
            spans.append((layout, lo, hi))
    if not spans:
        raise BagError(f'{bag.path}: no layout segment holds two motion samples')
    target = speed
    if target is None:
        lo, hi = (spans[segment - 1][1:] if segment is not None and 1 <= segment <= len(spans)
                  else (0, len(kept.stamp)))
        target = busiest_speed(kept.stamp[lo:hi], np.abs(kept.omega[lo:hi]), tolerance)
    segments = []
    for number, (layout, lo, hi) in enumerate(spans, 1):
        part = slice(lo, hi)
        try:
            stretches, note = tuple(steady_stretches(kept.stamp[part], kept.angle[part],
                                                     kept.omega[part], target or None,
                                                     tolerance)), ''
        except ValueError as error:
            stretches, note = (), str(error)
        segments.append(Segment(number, layout, float(kept.log[lo]), float(kept.log[hi - 1]),
                                stretches, note, int(log_ns[lo])))
    return kept, segments, problems


def segment_text(segment):
    """Return one line naming a segment: number, times, layout and its steady stretch."""
    layout = segment.layout
    where = f"layout '{layout.name}' ({layout.digest()})" if layout is not None \
        else 'no layout'
    text = f'segment {segment.number} ({segment.start:.3f}-{segment.end:.3f} s, {where})'
    window = segment.longest
    if window is None:
        return f'{text}: {segment.note}'
    return (f'{text}: steady {window.start:.3f}-{window.end:.3f} s at {window.speed:.4g} '
            f'rad/s, {window.revolutions} revolutions')


def choose_segment(path, segments, segment=None):
    """
    Return the :class:`Segment` to read: number ``segment``, or the longest steady one.

    Raises BagError naming the segments when the one asked for does not exist or has no
    steady stretch.
    """
    listing = '; '.join(segment_text(s) for s in segments)
    if segment is not None:
        if not 1 <= segment <= len(segments):
            raise BagError(f'{path}: --segment {segment}: the run has {len(segments)} layout '
                           f'segment{"s" if len(segments) > 1 else ""} ({listing})')
        chosen = segments[segment - 1]
        if chosen.longest is None:
            raise BagError(f'{path}: segment {segment} has no steady stretch to read: '
                           f'{chosen.note}')
        return chosen
    steady = [s for s in segments if s.longest is not None]
    if not steady:
        notes = '; '.join(dict.fromkeys(s.note for s in segments))
        raise BagError(f'{path}: {notes}')
    return max(reversed(steady), key=lambda s: s.longest.revolutions)


def angle_source(bag, names=None):
    """
    Return (where the angle comes from {kind, topic, type}, the motion's topics).

    ``kind`` 'encoder' (JointState), 'speed' (Float64, integrated) or 'keyphasor' (a
    once-per-revolution tach); the motion's topics are never vibration channels.
    """
    channels = input_channels(bag, names or InputTopics())
    if channels.keyphasor is not None:
        kind, channel = 'keyphasor', channels.keyphasor
    elif channels.joint_states is not None:
        kind, channel = 'encoder', channels.joint_states
    else:
        kind, channel = 'speed', channels.speed
    motion = [c.topic for c in (channels.speed, channels.keyphasor) if c is not None]
    return {'kind': kind, 'topic': channel.topic, 'type': channel.msg_type}, motion


def angle_text(angle_from):
    """Return where a run's angle came from, for people: 'the keyphasor /tach (...)'."""
    if not angle_from:
        return 'the encoder'
    kind, topic = angle_from['kind'], angle_from['topic']
    if kind == 'keyphasor':
        return (f"the keyphasor {topic} ({angle_from['type']}: 0 at each mark, interpolated "
                'between marks)')
    return f"the {'encoder' if kind == 'encoder' else 'speed'} {topic}"


def read_run(bag_path, sensors=None, speed=None, tolerance=DEFAULT_TOLERANCE,
             joint_name='gantry_joint', layout_file=None, max_speed=1000.0, segment=None,
             names=None):
    """
    Return the :class:`RunReadings` of a bag (see the module's description).

    ``sensors``: channel names to read (default: :func:`default_sensors`); ``speed``
    rad/s: read the steady stretch at that speed (default: the speed the run spent most
    time at); ``segment``: the layout segment's number (default: the one with the longest
    steady stretch); ``names``: the input topics (:class:`~cvc_balance.bag.inputs.
    InputTopics`; its ``keyphasor``: the angle from a tach). The stretch read lies inside
    one layout segment. Raises ValueError (BagError) naming what is missing.
    """
    bag = open_bag(bag_path)
    angle_from, motion_topics = angle_source(bag, names)
    motion, segments, problems = run_segments(bag, joint_name, layout_file, speed, tolerance,
                                              max_speed, segment, names)
    chosen = choose_segment(bag.path, segments, segment)
    window, layout = chosen.longest, chosen.layout
    stamp, log, angle = motion.stamp, motion.log, motion.angle
    sources = channel_sources(bag, motion_topics)
    wanted = default_sensors(sources, layout) if sensors is None else list(sensors)
    missing = [n for n in wanted if n not in sources]
    if missing or not wanted:
        found = ', '.join(sources) or 'none'
        said = [m for m in missing if m.strip('/') in (t.strip('/') for t in motion_topics)]
        raise BagError(f'{bag.path}: no channel {", ".join(missing) or "to read"} (channels: '
                       f'{found}; load cells are supports/<name>/measured_load, other '
                       'channels std_msgs/Float64, Vector3Stamped or Imu topics'
                       + (f'; {", ".join(said)} is the motion, never a vibration channel'
                          if said else '') + ')')
    log_window = type(window)(float(np.interp(window.start, stamp, log)),
                              float(np.interp(window.end, stamp, log)), window.speed,
                              window.revolutions, window.spread)
    phasors, units, cache, vibrations = {}, {}, {}, {}
    for name in wanted:
        channel, index, unit = sources[name]
        if isinstance(index, int):
            if channel.id not in cache:
                cache[channel.id] = wrench_samples(bag, channel)
            stamps, force, torque = cache[channel.id]
            values = np.concatenate([force, torque], axis=1)[:, index]
            times, motion_time, used = stamps * 1e-9, stamp, window
        else:
            samples = channel_samples(bag, index, vibrations)
            values = samples.values
            times = samples.time * 1e-9
            # Float64 carries no stamp: its log time, against the motion's log times.
            motion_time, used = (log, log_window) if index.axis is None else (stamp, window)
        try:
            phasors[name] = track(times, values, motion_time, angle, used)
        except ValueError as error:
            raise BagError(f'{bag.path}: channel {name}: {error}') from None
        units[name] = unit
    return RunReadings(str(bag_path), window, log_window, phasors, units, layout,
                       int(round(log[0] * 1e9)), problems, chosen.number, tuple(segments),
                       names, angle_from)


def calibrate_runs(baseline_path, trial_paths, trials, keep_trial=False, sensors=None,
                   speed=None, tolerance=DEFAULT_TOLERANCE, joint_name='gantry_joint',
                   layout_file=None, segments=None, names=None):
    """
    Return (Calibration, [RunReadings], warnings) of a baseline run and trial runs.

    ``trials``: one :class:`~cvc_balance.field.influence.Trial` (kg, rad, m) per trial
    run, in order. Every run is read at the baseline's steady speed (or ``speed``), each
    inside one layout segment: ``segments`` one number per run, or one for every run
    (None: each run's longest steady one); ``names`` the input topics of every run
    (:class:`~cvc_balance.bag.inputs.InputTopics`: a keyphasor instead of the encoder).
    """
    if len(trial_paths) != len(trials):
        raise ValueError(f'{len(trial_paths)} trial runs but {len(trials)} --trial weights: '
                         'give one --trial per trial run, in order')
    count = 1 + len(trial_paths)
    segments = [None] * count if not segments else list(segments)
    if len(segments) == 1:
        segments *= count
    if len(segments) != count:
        raise ValueError(f'--segment: give one number for every run or one per run ({count}), '
                         f'got {len(segments)}')
    baseline = read_run(baseline_path, sensors, speed, tolerance, joint_name, layout_file,
                        segment=segments[0], names=names)
    if baseline.layout is not None and baseline.layout.correction_planes() is not None:
        try:
            plane_positions(baseline.layout, dict.fromkeys(t.plane for t in trials))
        except ValueError as error:
            raise ValueError(f'--trial: {error}') from None
    sensors = list(baseline.phasors)
    at = baseline.window.speed if speed is None else speed
    runs = [baseline] + [read_run(p, list(baseline.phasors), at, tolerance, joint_name,
                                  layout_file, segment=n, names=names)
                         for p, n in zip(trial_paths, segments[1:])]
    warnings = []
    for k, run in enumerate(runs[1:]):
        off = abs(run.window.speed / baseline.window.speed - 1.0)
        if off > SPEED_MISMATCH:
            warnings.append(f'trial run {k + 1} ({run.bag}) is at {run.window.speed:.4g} '
                            f'rad/s, {off:.1%} off the baseline\'s {baseline.window.speed:.4g}: '
                            'readings grow with speed (forces as its square)')
        if None not in (run.layout, baseline.layout) \
                and run.layout.digest() != baseline.layout.digest():
            warnings.append(f"trial run {k + 1} ({run.bag}) is read under layout "
                            f"'{run.layout.name}' ({run.layout.digest()}), the baseline under "
                            f"'{baseline.layout.name}' ({baseline.layout.digest()}): the "
                            'coefficients take the baseline\'s')
    calibration = calibrate(
        [baseline.phasors[n].value for n in sensors], trials,
        [[run.phasors[n].value for n in sensors] for run in runs[1:]], sensors, keep_trial,
        [baseline.phasors[n].sigma for n in sensors],
        [[run.phasors[n].sigma for n in sensors] for run in runs[1:]])
    return calibration, runs, warnings


def permissible_unbalance(layout, speed):
    """Return the rotor's permissible unbalance (kg m) by its layout's grade, at ``speed``."""
    model = RotorModel.from_layout(layout)
    return iso21940.permissible_unbalance(layout.balancing.grade, model.mass,
                                          layout.balancing.service_speed or speed)


def check_calibration(calibration, runs, trials, keep_trial=False):
    """
    Return the :class:`~cvc_balance.field.model_check.ModelCheck` of a run calibration.

    The baseline's layout (its segment's, or the layout file) predicts the load cells'
    coefficients at the baseline's speed; without a layout nothing is checked.
    """
    baseline = runs[0]
    layout = baseline.layout
    if layout is None:
        return ModelCheck(False, 'no layout in the baseline run (give --layout-file): the '
                          'coefficients are not checked against physics')
    return check_coefficients(layout, calibration, baseline.window.speed, trials, keep_trial,
                              permissible_unbalance(layout, baseline.window.speed))


def layout_sensors(layout):
    """Return the load-cell channels a layout predicts: each support's force x, y (moments)."""
    single = len(layout.supports) == 1
    return [f'{s.name}/{c}' for s in layout.supports
            for c in ('force_x', 'force_y') + (('torque_x', 'torque_y') if single else ())]


def trial_advice(run_path=None, layout_file=None, standard_errors=20.0, sigma=None,
                 speed=None, segment=None, tolerance=DEFAULT_TOLERANCE,
                 joint_name='gantry_joint', names=None):
    """
    Return (advice per plane, RunReadings or None, layout, speed): trial weights to use.

    From a baseline run (its load cells' standard errors, its layout segment's layout or
    ``layout_file``, its steady speed) or from ``layout_file`` alone (``sigma``: the 1x
    standard error of the cells' readings, N, if known; ``speed`` rad/s, default the
    layout's service speed). See :mod:`cvc_balance.field.trial_weight`.
    """
    run = None
    if run_path is not None:
        run = read_run(run_path, None, speed, tolerance, joint_name, layout_file,
                       segment=segment, names=names)
        layout, speed = run.layout, run.window.speed
        if layout is None:
            raise BagError(f'{run_path}: no layout in the run: give --layout-file')
    else:
        if layout_file is None:
            raise ValueError('give a baseline run, or the layout with --layout-file')
        from cvc_balance.physics.layout_file import load_layout
        layout = load_layout(layout_file)
        speed = speed or layout.balancing.service_speed
        if not speed:
            raise ValueError(f"{layout_file}: the layout has no balancing.service_speed: give "
                             '--speed (rad/s of the trial runs)')
    if layout.correction_planes() is None:
        raise ValueError(f"layout '{layout.name}' has no two correction planes "
                         '(balancing.planes, or two supports)')
    planes = ('I', 'II')
    sensors = layout_sensors(layout)
    if run is not None:
        sensors = [n for n in sensors if n in run.phasors]
        if not sensors:
            raise BagError(f'{run_path}: no load cell of the layout\'s supports in the run '
                           '(supports/<name>/measured_load): no standard errors to size a '
                           'trial by; give --layout-file alone for the starting rule')
        sigma = [run.phasors[n].sigma for n in sensors]
    elif sigma is not None:
        sigma = [sigma] * len(sensors)
    predicted, _ = predicted_coefficients(layout, sensors, planes, speed)
    advice = advise(layout, planes, plane_positions(layout, planes), predicted, sensors,
                    speed, sigma, standard_errors)
    return advice, run, layout, speed


@dataclass
class GradeView:
    """
    The rotor's balance per correction plane against its ISO 21940-11 grade.

    ``planes`` names ('I', 'II'); ``z`` m; ``before`` complex kg m (identified) with its
    95 % radius ``ci95``; ``permissible`` kg m per plane; ``grade`` G mm/s at ``speed``
    rad/s; ``mass`` kg and ``shares`` (ISO allocation) to turn amounts into a grade;
    ``source`` what ``before`` comes from.
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
    source: str = 'the load cells'

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
    ``warnings`` one line each; ``objective`` and ``max_weights`` of the optimal plan;
    ``model_check`` the coefficients against the layout's physics (None without
    coefficients); ``segment_grades`` a GradeView or None per segment of the run;
    ``existing`` the PlacedWeights on already (a trim); ``verdict`` the verdict of record
    from vibration readings through coefficients (None otherwise).
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
    model_check: object = None
    segment_grades: tuple = ()
    existing: tuple = ()
    verdict: object = None


def _check_correction_masses(layout, planes, correction, radius, sites):
    """Refuse corrections heavier than the whole rotor: the radius they sit at is wrong."""
    mass = RotorModel.from_layout(layout).mass
    for plane, value in zip(planes, correction):
        r = radius.get(plane)
        if r and abs(value) / r > mass:
            where = f'balancing.sites.{plane}.radius' if plane in sites \
                else 'balancing.correction_radius'
            raise ValueError(f'plane {plane}: the correction needs {abs(value) / r:.3g} kg at '
                             f'r {r:.3g} m ({where}), more than the whole rotor\'s '
                             f'{mass:.4g} kg: that radius cannot be right')


def identify_segment(bag_path, segment, joint_name='gantry_joint', max_speed=1000.0,
                     time_constant=0.1, names=None):
    """
    Return the RotorUnbalance the load cells identify over one :class:`Segment`, or None.

    The segment's own layout and samples only (never across a layout change), the motion
    and alpha as ``identify`` takes them (``names``: its input topics); None without
    cells or when not identifiable.
    """
    if segment.layout is None:
        return None
    bag = open_bag(bag_path)
    motion, _ = read_inputs(bag, joint_name, names)
    t = motion.stamp * 1e-9
    accepted, alpha = accepted_motion(t, motion.log_time * 1e-9, motion.angle, motion.omega,
                                      max_speed, time_constant)
    log = motion.log_time[accepted] * 1e-9
    inside = (log >= segment.start) & (log <= segment.end)
    if np.count_nonzero(inside) < 2:
        return None
    seg = Motion(t[accepted][inside], motion.angle[accepted][inside],
                 motion.omega[accepted][inside], alpha[inside])
    model = RotorModel.from_layout(segment.layout)
    cells = {}
    for name, cell in cell_readings(bag, model.supports).items():
        keep = (cell.time >= seg.time[0]) & (cell.time <= seg.time[-1])
        cells[name] = CellReadings(cell.support, cell.time[keep], cell.force[keep],
                                   cell.torque[keep])
    if not cells:
        return None
    estimate, _ = fit(model, seg, cells)
    if not (estimate.readings and estimate.identifiable):
        return None
    return identified_unbalance(model, estimate)


def grade_view(run, joint_name='gantry_joint', segment=None):
    """
    Return the :class:`GradeView` of a run (RunReadings) from its load cells, or None.

    None when the bag has no load cells or no layout with two correction planes. The
    cells are fitted over the run's layout segment (``segment``: another
    :class:`Segment` of it, whose layout a layout file has replaced); the grade is
    judged at the layout's service speed (default: the run's steady speed).
    """
    segment = run.chosen if segment is None else segment
    layout = segment.layout
    if layout is None or layout.correction_planes() is None:
        return None
    identified = identify_segment(run.bag, segment, joint_name, names=run.names)
    if identified is None or not identified.planes:
        return None
    model = RotorModel.from_layout(layout)
    z = layout.correction_planes()
    planes = identified.planes
    steady = segment.longest
    speed = layout.balancing.service_speed or (steady.speed if steady else run.window.speed)
    shares = iso21940.plane_shares(model.s_z / model.mass, *z)
    u_per = iso21940.permissible_unbalance(layout.balancing.grade, model.mass, speed)
    return GradeView(('I', 'II'), tuple(z), np.array([v.value for _, v in planes]),
                     tuple(v.ci95 for _, v in planes), np.array([u_per * s for s in shares]),
                     layout.balancing.grade, speed, model.mass, shares)


def correct_run(run_path, calibration=None, record=None, layout_file=None,
                objective=None, limit=None, max_weights=None, tolerance=DEFAULT_TOLERANCE,
                joint_name='gantry_joint', time_limit=30.0, segment=None,
                accept_mismatch=False, speed=None, weights_on=(), names=None,
                identity=None):
    """
    Return the :class:`FieldCorrection` of a run (see the module's description).

    With ``calibration`` (and its ``record``: speed, units) the run's readings of the
    calibrated sensors are corrected (``limit``: largest residual reading allowed);
    without, the unbalance its load cells identify is, against the layout's grade. Limits
    keep the readings' (or the identification's) 95 % radius to spare. ``objective``
    'fewest' (default when there are limits) or 'residual' (at most ``max_weights``
    weights, default two per plane with sites). Sites and the grade come from
    ``layout_file`` or the bag's layout; ``segment`` the layout segment to read (default:
    the one with the longest steady stretch); ``speed`` the steady speed to read (default
    the record's; coefficients made at another are scaled, :func:`~cvc_balance.field.
    coefficients.at_speed`). Coefficients that disagree with the layout's physics raise
    ValueError naming the likely mistake, unless ``accept_mismatch``. ``weights_on``: the
    weights bolted on already (:func:`weights_on_sites`): the plans may take them off.
    ``names``: the run's input topics (a keyphasor instead of the encoder); ``identity``
    the coefficients' record named (:func:`coefficients_identity`): without load cells,
    the verdict of record is then measured by the vibration sensors through them
    (``FieldCorrection.verdict``), unless they were made on another layout.
    """
    warnings = []
    speed = speed or (None if record is None else record.get('speed'))
    sensors = None if calibration is None else list(calibration.sensors)
    run = read_run(run_path, sensors, speed, tolerance, joint_name, layout_file,
                   segment=segment, names=names)
    layout = run.layout
    grades = tuple(grade_view(run, joint_name=joint_name, segment=s) for s in run.segments)
    grade = grades[run.segment - 1]
    if calibration is None:
        if grade is None:
            raise BagError(f'{run_path}: no load cells to identify the unbalance from (topics '
                           'supports/<name>/measured_load) or no layout with two correction '
                           'planes: give --coefficients from trial runs')
        problem = problem_from_unbalance(grade.planes, grade.before,
                                         grade.permissible - np.asarray(grade.ci95))
        if not np.all(problem.limits > 0.0):
            raise ValueError('the identified unbalance is uncertain by more than the grade '
                             'allows (95 % radius over U_per): record a longer run')
        return _corrections(run, 'identified unbalance', problem, layout, grade, warnings,
                            objective, max_weights, time_limit, None, grades, weights_on)
    calibration, check = _checked(calibration, record, layout, run.window.speed,
                                  accept_mismatch, warnings)
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
    verdict = None
    if grade is None and identity is not None:
        grade, verdict = _coefficient_verdict(run, calibration, record, identity, problem,
                                              layout, warnings)
    elif grade is None:
        grade = coefficient_grade(problem, layout, run.window.speed)
    result = _corrections(run, 'influence coefficients', problem, layout, grade, warnings,
                          objective, max_weights, time_limit, check, grades, weights_on)
    result.verdict = verdict
    return result


def _coefficient_verdict(run, calibration, record, identity, problem, layout, warnings):
    """
    Return (GradeView or None, VerdictOfRecord or None) of a run read through coefficients.

    The verdict of record measured by the vibration sensors through the coefficients
    (:func:`~cvc_balance.identify.evidence.verdict_of_record` of a PlaneEstimate); when
    they were made on another layout (digest) the layout's verdict stands, saying why,
    and no measured grade is shown.
    """
    from cvc_balance.field.coefficients import plane_unbalance
    from cvc_balance.identify.evidence import PlaneEstimate, verdict_of_record
    if layout is None or layout.correction_planes() is None or problem.unit != 'kg m' \
            or set(problem.planes) != {'I', 'II'}:
        return coefficient_grade(problem, layout, run.window.speed), None
    model = RotorModel.from_layout(layout)
    made_on = record.get('layout') if isinstance(record.get('layout'), dict) else None
    if made_on and made_on.get('digest') != layout.digest():
        reason = (f"coefficients {identity['file']}: made on layout '{made_on.get('name')}' "
                  f"({made_on.get('digest')}), this run's is '{layout.name}' "
                  f'({layout.digest()}): not this machine type')
        warnings.append(reason)
        return None, verdict_of_record(model, None, run.window.speed,
                                       no_measurement=reason, coefficients=identity)
    by = f"the vibration sensors through coefficients {identity['file']}"
    grade = coefficient_grade(problem, layout, run.window.speed, by)
    sensors = list(calibration.sensors)
    u, covariance = plane_unbalance(calibration, [run.phasors[n].value for n in sensors],
                                    [run.phasors[n].sigma for n in sensors])
    order = [calibration.planes.index(p) for p in ('I', 'II')]
    estimate = PlaneEstimate(
        tuple(layout.correction_planes()), tuple(complex(u[k]) for k in order),
        tuple(tuple(complex(covariance[i, j]) for j in order) for i in order), by, identity,
        min(p.samples for p in run.phasors.values()))
    verdict = verdict_of_record(model, estimate, run.window.speed)
    if grade is not None:
        grade.ci95 = tuple(estimate.ci95(w) for w in plane_weights(estimate.z))
    return grade, verdict


def plane_weights(z):
    """Return the (w_S, w_P) that pick u_I and u_II out of S and P about O (planes at z)."""
    span = z[1] - z[0]
    return ((z[1] / span, -1.0 / span), (-z[0] / span, 1.0 / span))


@dataclass
class HandReadings:
    """
    Readings typed in by hand: ``readings`` {sensor: complex} at ``speed`` rad/s (or None).

    ``units`` {sensor: unit}; ``layout`` the layout file's, or None.
    """

    readings: dict
    units: dict
    speed: float
    layout: object


def correct_readings(readings, calibration, record, layout_file=None, objective=None,
                     limit=None, max_weights=None, speed=None, time_limit=30.0,
                     accept_mismatch=False, weights_on=()):
    """
    Return the :class:`FieldCorrection` of readings by hand with stored coefficients.

    ``readings`` complex, one per sensor of the record, in its order; ``speed`` rad/s of
    the readings (default the record's: a record made at another speed is scaled or
    refused, :func:`~cvc_balance.field.coefficients.at_speed`); ``layout_file`` gives the
    sites, the kit and the grade (the unbalance the readings imply through the
    coefficients) and checks the coefficients against its physics. The same problem as
    ``influence``'s: every sensor weighs alike, so the corrections equal a fresh
    ``influence``'s to the bit.
    """
    warnings = []
    readings = [complex(r) for r in readings]
    if len(readings) != len(calibration.sensors):
        raise ValueError(f'--readings: the coefficients name {len(calibration.sensors)} '
                         f'sensors ({", ".join(calibration.sensors)}), got {len(readings)} '
                         'readings')
    layout = None
    if layout_file is not None:
        from cvc_balance.physics.layout_file import load_layout
        layout = load_layout(layout_file)
    speed = speed or (record or {}).get('speed')
    calibration, check = _checked(calibration, record, layout, speed, accept_mismatch,
                                  warnings)
    unit = (record or {}).get('correction_unit', 'kg m')
    limits = None if limit is None else np.full(len(readings), float(limit))
    problem = problem_from_readings(calibration, readings, None, limits, unit)
    units = list((record or {}).get('reading_units') or ['as read'] * len(readings))
    run = HandReadings(dict(zip(calibration.sensors, readings)),
                       dict(zip(calibration.sensors, units)), speed, layout)
    grade = coefficient_grade(problem, layout, speed)
    return _corrections(run, 'influence coefficients', problem, layout, grade, warnings,
                        objective, max_weights, time_limit, check, (), weights_on,
                        {t.plane: t.radius for t in record_trials(record)} if layout is None
                        else {})


def _checked(calibration, record, layout, speed, accept_mismatch, warnings):
    """Return (coefficients at ``speed``, ModelCheck); the check's refusal raised."""
    calibration, note = at_speed(calibration, record, speed)
    if note:
        warnings.append(note)
    check = ModelCheck(False, 'no layout (give --layout-file): the coefficients are not checked '
                       'against physics')
    if layout is not None and speed:
        check = check_coefficients(layout, calibration, speed, record_trials(record),
                                   bool((record or {}).get('keep_trial')),
                                   permissible_unbalance(layout, speed))
    elif layout is not None:
        check = ModelCheck(False, 'no speed of the readings (give --speed): the coefficients '
                           'are not checked against physics')
    if check.mismatch:
        if not accept_mismatch:
            raise ValueError(check.refusal)
        warnings.append(check.message)
    warnings += list(calibration.warnings)
    return calibration, check


def coefficient_grade(problem, layout, speed, source='the readings through the coefficients'):
    """
    Return the :class:`GradeView` of the unbalance readings imply through coefficients.

    The unbalance per plane is minus the continuous correction (what the corrections
    cancel), kg m; None unless the corrections are in kg m for the layout's planes I and
    II. No 95 % radius (the readings' noise is not known): 0.
    """
    if layout is None or problem.unit != 'kg m' or set(problem.planes) != {'I', 'II'} \
            or layout.correction_planes() is None:
        return None
    before = -continuous_correction(problem)
    order = [problem.planes.index(p) for p in ('I', 'II')]
    model = RotorModel.from_layout(layout)
    z = layout.correction_planes()
    service = layout.balancing.service_speed or speed
    if not service:
        return None
    shares = iso21940.plane_shares(model.s_z / model.mass, *z)
    u_per = iso21940.permissible_unbalance(layout.balancing.grade, model.mass, service)
    return GradeView(('I', 'II'), tuple(z), before[order], (0.0, 0.0),
                     np.array([u_per * s for s in shares]), layout.balancing.grade, service,
                     model.mass, shares, source)


def weights_on_sites(layout, specs):
    """
    Return the PlacedWeights of weights bolted on already, at the layout's sites.

    ``specs``: (plane, ('angle', rad) or ('hole', number), mass kg) each
    (:func:`cvc_balance.field.notation.weight_on`). Raises ValueError naming a plane
    without sites, an angle with no site, a hole that does not exist, or a site overfull.
    """
    if not specs:
        return ()
    sites = {s.plane: s for s in layout.balancing.sites} if layout is not None else {}
    stacks = {}
    for plane, (kind, where), mass in specs:
        plane_sites = sites.get(plane)
        if plane_sites is None:
            raise ValueError(f'--weights-on: plane {plane} has no weight sites in the layout '
                             f'(balancing.sites names {", ".join(sites) or "none"})')
        if kind == 'hole':
            angle = site_of_hole(plane_sites, where)
        else:
            angle = next((a for a in plane_sites.angles
                          if abs(math.remainder(a - where, 2.0 * math.pi)) < 1e-6), None)
            if angle is None:
                raise ValueError(f'--weights-on: plane {plane} has no site at '
                                 f'{math.degrees(where):g} deg (sites every '
                                 f'{_site_list(plane_sites)})')
        stacks.setdefault((plane, angle), []).append(mass)
    out = []
    for (plane, angle), masses in sorted(stacks.items()):
        if len(masses) > sites[plane].stack:
            raise ValueError(f'--weights-on: {len(masses)} weights at one site of plane {plane} '
                             f'({math.degrees(angle):g} deg): its stack holds '
                             f'{sites[plane].stack}')
        out.append(PlacedWeight(plane, angle, sites[plane].radius,
                                tuple(sorted(masses, reverse=True))))
    return tuple(out)


def _site_list(sites):
    shown = ', '.join(f'{math.degrees(a):g}' for a in sorted(sites.angles)[:6])
    return shown + (' ...' if len(sites.angles) > 6 else '') + ' deg'


def _corrections(run, method, problem, layout, grade, warnings, objective, max_weights,
                 time_limit, check, grades, weights_on=(), trial_radii=None):
    """Return the :class:`FieldCorrection`: the continuous, split and optimal plans."""
    sites = {s.plane: s for s in layout.balancing.sites} if layout is not None else {}
    existing = weights_on_sites(layout, weights_on)
    radius = {}
    for plane in problem.planes:
        if plane in sites:
            radius[plane] = sites[plane].radius
        elif layout is not None and layout.correction_radius() > 0.0:
            radius[plane] = layout.correction_radius()
        else:
            radius[plane] = (trial_radii or {}).get(plane)
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
    if layout is not None and problem.unit == 'kg m':
        _check_correction_masses(layout, problem.planes, continuous, radius, sites)
    plans = [continuous_plan(problem, continuous)]
    if used_sites:
        plans.append(split_plan(problem, used_sites, continuous))
        plans.append(optimal_plan(problem, used_sites, objective, max_weights,
                                  time_limit=time_limit, existing=existing))
    return FieldCorrection(run, method, problem, plans, used_sites, radius, grade, warnings,
                           objective, max_weights, check, grades, existing)


@dataclass(frozen=True)
class CoefficientReading:
    """
    One layout segment's unbalance from vibration readings through stored coefficients.

    ``segment`` the :class:`Segment`; ``estimate`` the
    :class:`~cvc_balance.identify.evidence.PlaneEstimate` (None when the coefficients do
    not fit this segment: ``reason`` one line why); ``run`` the :class:`RunReadings` read
    (None when nothing was read); ``identity`` the coefficients' record named.
    """

    segment: Segment
    estimate: object
    reason: str
    run: object
    identity: dict


def coefficients_identity(path, record):
    """
    Return the coefficients' record named, as plain data, for the verdict's JSON and text.

    ``file`` (as given), ``sha256`` (the file's bytes, 16 hex digits), ``made`` (the
    baseline run's date, or None by hand), ``layout`` {name, digest} the record was made
    on (or None), ``speed`` rad/s (or None), ``sensors`` and ``reading_units``.
    """
    import hashlib
    from pathlib import Path
    runs = [r for r in record.get('runs') or () if isinstance(r, dict)]
    return {'file': str(path),
            'sha256': hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16],
            'made': next((r.get('date') for r in runs if r.get('date')), None),
            'layout': record.get('layout'), 'speed': record.get('speed'),
            'sensors': list(record.get('sensors') or ()),
            'reading_units': list(record.get('reading_units') or ())}


def coefficient_readings(bag_path, calibration, record, identity, names=None,
                         layout_file=None, tolerance=DEFAULT_TOLERANCE,
                         joint_name='gantry_joint'):
    """
    Return a :class:`CoefficientReading` per layout segment of a bag: readings = C u solved.

    The coefficients' sensors are read over each segment's longest steady stretch at the
    record's speed (:func:`read_run`); they fit the segment when they are kg m per
    planes I and II, made on the segment's layout (same digest, when the record names
    one), at its speed (:func:`~cvc_balance.field.coefficients.at_speed`: within 0.1 %,
    or scaled for load cells) and every sensor is in the bag. Else ``reason`` says which,
    in one line, and the verdict stays the layout's.
    """
    from cvc_balance.field.coefficients import plane_unbalance
    from cvc_balance.identify.evidence import PlaneEstimate
    bag = open_bag(bag_path)
    speed = record.get('speed')
    _, segments, _ = run_segments(bag, joint_name, layout_file, speed, tolerance,
                                  names=names)
    file = identity['file']
    made_on = record.get('layout') if isinstance(record.get('layout'), dict) else None
    out = []
    for segment in segments:
        def unfit(reason, run=None, segment=segment):
            return CoefficientReading(segment, None, f'coefficients {file}: {reason}', run,
                                      identity)
        layout = segment.layout
        if record.get('correction_unit') != 'kg m' or set(calibration.planes) != {'I', 'II'}:
            out.append(unfit(f"per {record.get('correction_unit')} in planes "
                             f"{', '.join(calibration.planes)}, not kg m in planes I and II: "
                             'no unbalance in g mm'))
            continue
        if layout is None or layout.correction_planes() is None:
            out.append(unfit('the segment has no layout with two correction planes to '
                             'judge the unbalance in'))
            continue
        if made_on and made_on.get('digest') != layout.digest():
            out.append(unfit(f"made on layout '{made_on.get('name')}' ({made_on.get('digest')}"
                             f"), this segment's is '{layout.name}' ({layout.digest()}): "
                             'not this machine type'))
            continue
        if segment.longest is None:
            at = f'the coefficients\' {speed:.4g} rad/s' if speed else 'a steady speed'
            out.append(unfit(f'no steady stretch at {at} (+-{tolerance:.1%}) in this '
                             f'segment: {segment.note}'))
            continue
        try:
            run = read_run(bag_path, list(calibration.sensors), speed, tolerance, joint_name,
                           layout_file, segment=segment.number, names=names)
            scaled, _ = at_speed(calibration, record, run.window.speed)
        except ValueError as error:
            out.append(unfit(str(error).replace(f'{bag.path}: ', '')))
            continue
        readings = [run.phasors[n].value for n in calibration.sensors]
        sigma = [run.phasors[n].sigma for n in calibration.sensors]
        u, covariance = plane_unbalance(scaled, readings, sigma)
        order = [calibration.planes.index(p) for p in ('I', 'II')]
        estimate = PlaneEstimate(
            tuple(layout.correction_planes()), tuple(complex(u[k]) for k in order),
            tuple(tuple(complex(covariance[i, j]) for j in order) for i in order),
            f'the vibration sensors through coefficients {file}', identity,
            min(p.samples for p in run.phasors.values()))
        out.append(CoefficientReading(segment, estimate, None, run, identity))
    return out
