"""
The rerun view of a run, laid out to be read at a glance.

One logger for both paths (the live node and ``cvc-balance view`` of a bag), on the
timeline ``time`` (the samples' stamps). Every panel names its units. What it logs:

* ``world`` (the lab: gravity along -Y, ``frames.stator_tilt``): ``world/stator``
  tilted as the gantry is, with its ring, supports and an arrow for the load at each
  support (20 kN per metre, labelled in kN); ``world/stator/rotor`` turning with q,
  each component as its shape at (R, theta, z), the component a layout change
  touched highlighted (and named with what changed), labels only where they do not
  crowd a more important one (``LABEL_SPACING``), the correction planes with the
  correction masses, and the static unbalance's force U omega^2 (200 N per metre).
* ``plots``: per correction plane its unbalance as a fraction of its OWN permissible
  share (1.0 = that plane's limit, at the speed the verdict is judged at, so speed
  does not squash it); omega and alpha; the drive torque; per support the static
  weight beside the rotating part's amplitude and the peak over a turn
  (:mod:`cvc_balance.physics.load_parts`); where the layout describes the supports'
  bearings, each bearing's life used since the run's start (a fraction of its rating
  life, :mod:`cvc_balance.physics.bearing_life`, counted over the samples logged).
* ``polar/<plane>``: a polar diagram per plane in the same fractions: angle grid,
  the 0 deg mark (rotor X), angles counter-clockwise as in the rotor frame (rerun's
  2D views point Y down, so points are drawn at (x, -y)), the tolerance circle
  labelled with its g mm, the unbalance and the correction vector, labels placed
  apart.
* ``verdict_level`` (coloured lanes: OK green, WARN amber, ERROR red), ``verdict``
  (the verdict of :func:`cvc_balance.physics.assessment.judge_balance`, the same as
  the node's diagnostics, ``solve`` and ``replay``), ``events`` (layout changes,
  plausibility warnings, verdicts, coloured by level).

The rerun SDK is imported here only (an adapter).
"""

import math
from types import SimpleNamespace

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import rerun.blueprint.encodings as rre

from cvc_balance.identify.evidence import MEASURED
from cvc_balance.physics import assessment
from cvc_balance.physics.assessment import assess_balance, judge_balance, WARN_FRACTION
from cvc_balance.physics.bearing_life import LifeCounters
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.frames import degrees_360, g_mm, stator_tilt
from cvc_balance.physics.load_parts import support_load_parts
from cvc_balance.physics.plausibility import layout_warnings
from cvc_balance.physics.unbalance import plane_unbalances, static_unbalance, unbalance_wrench

TIMELINE = 'since start'
"""The timeline the views show: seconds since the run's first sample (a duration)."""
STAMP_TIMELINE = 'time'
"""The samples' own stamps (UTC): where the run sits in other logs (a timestamp)."""
NEWTONS_PER_METRE = 20000.0
"""Support load arrows: 20 kN per metre of arrow."""
UNBALANCE_NEWTONS_PER_METRE = 200.0
"""Unbalance force arrow: 200 N per metre (a balanced gantry's is tens of newtons)."""
LONGEST_ARROW = 1.0
"""m: longer arrows are drawn this long (their label or plot gives the value)."""
PLANES = ('plane_I', 'plane_II')
STATOR_RING_RADIUS = 0.85      # m, drawn for orientation
VIEW_PIXELS = 500
"""Pixels across the rotor in a typical 3D view: a shape under two of them is a point."""
LABEL_SPACING = 0.4
RESIDUAL_COLOUR = (170, 90, 220)
"""The load cells' residual (measured - layout) in the polar views and events."""
"""m: a 3D label this close to a more important one is left out (hover shows the name)."""
POLAR_REACH = 1.4
"""Longest vector drawn in the polar views (fraction of the limit); its label gives more."""
POLAR_BOUNDS = (2.0, -2.35, 2.6)
"""Half-width, top and bottom of the polar views (fractions of the limit; Y down)."""
POLAR_TEXT_ROW = 1.95
"""Where the polar views write the vectors' values: above and below the grid."""
POLAR_LINE = 0.28
"""A row of text in the polar views (fractions of the limit)."""

LEVEL_COLOURS = {assessment.OK: (60, 180, 90), assessment.WARN: (245, 170, 30),
                 assessment.ERROR: (235, 60, 60), assessment.NOT_JUDGED: (140, 140, 140)}
LOG_LEVELS = {assessment.OK: 'INFO', assessment.WARN: 'WARN', assessment.ERROR: 'ERROR',
              assessment.NOT_JUDGED: 'INFO'}
PLANE_COLOURS = {'plane_I': (80, 170, 255), 'plane_II': (255, 150, 220),
                 'static': (80, 170, 255)}
MEASURED_PLANE_COLOURS = {'plane_I': (20, 90, 230), 'plane_II': (190, 20, 120),
                          'static': (20, 90, 230)}
"""A plane's unbalance as the load cells measure it: its layout colour, deeper."""
COMPONENT_COLOUR = (120, 135, 160)
CHANGED_COLOUR = (255, 215, 0)
CORRECTION_COLOUR = (60, 200, 90)
LOAD_COLOUR = (255, 150, 30)
UNBALANCE_COLOUR = (235, 60, 60)
GRID_COLOUR = (90, 90, 100)
PREDICTED_COLOUR = (235, 235, 235)
"""A load cell's force as the layout predicts it, beside the measured one."""
SUPPORT_COLOURS = ((80, 170, 255), (255, 150, 30), (180, 120, 255))


EVENT_COLUMNS = rrb.TextLogColumns(
    timeline_columns=[rre.TimelineColumn(TIMELINE, visible=False),
                      rre.TimelineColumn(STAMP_TIMELINE, visible=False),
                      rre.TimelineColumn('log_time', visible=False)],
    text_log_columns=[rre.TextLogColumn('EntityPath', visible=False),
                      rre.TextLogColumn('LogLevel'), rre.TextLogColumn('Body')])


def plane_keys(layout):
    """Entity names of the judged planes: plane_I, plane_II, or 'static' without planes."""
    return PLANES if layout.correction_planes() is not None else ('static',)


def blueprint(support_names, planes=PLANES, static_range=None, cells=False, life=False):
    """
    Arrange the views: 3D and polar left, two columns of plots, verdict and events right.

    The plots of the rotor's motion and verdict in one column, those of the supports in
    the other, so that each is tall enough for its tick labels and its legend (a legend
    taller than its plot drops entries). ``static_range`` (N, N): the static weight
    plot's axis (a constant line would otherwise be fitted to its rounding). ``cells``:
    a plot per support's load cell (measured against the layout's prediction); ``life``: a
    plot of the bearings' life used since the start.
    """
    motion = [rrb.StateTimelineView(origin='verdict_level', name='verdict over time '
                                    '(OK, WARN, ERROR)'),
              rrb.TimeSeriesView(origin='plots/unbalance', name='unbalance per plane / its limit',
                                 plot_legend=rrb.PlotLegend('LeftTop')),
              rrb.TimeSeriesView(origin='plots/speed', name='speed ω, acceleration α',
                                 plot_legend=rrb.PlotLegend('LeftTop')),
              rrb.TimeSeriesView(origin='plots/drive_torque', name='drive torque [N m]',
                                 plot_legend=rrb.PlotLegend('RightTop'))]
    loads = [rrb.TimeSeriesView(origin='plots/load_rotating', name='rotating load per support [N]',
                                plot_legend=rrb.PlotLegend('LeftTop')),
             rrb.TimeSeriesView(origin='plots/load_static', name='static weight per support [N]',
                                plot_legend=rrb.PlotLegend('RightBottom'),
                                axis_y=rrb.ScalarAxis(range=list(static_range))
                                if static_range else None)]
    if cells:
        loads += [rrb.TimeSeriesView(origin=f'plots/cells/{name}',
                                     name=f'{name} load cell x, less its zero [N]',
                                     plot_legend=rrb.PlotLegend('LeftTop'))
                  for name in support_names]
    if life:
        loads.append(rrb.TimeSeriesView(origin='plots/life',
                                        name='bearing life used since start (of its rating life)',
                                        plot_legend=rrb.PlotLegend('LeftTop')))
    bounds = rrb.VisualBounds2D(x_range=[-POLAR_BOUNDS[0], POLAR_BOUNDS[0]],
                                y_range=list(POLAR_BOUNDS[1:]))
    polar = [rrb.Spatial2DView(origin=f'polar/{key}', name=_polar_title(key),
                               visual_bounds=bounds) for key in planes]
    gantry = rrb.Spatial3DView(
        origin='world', name='gantry [m]; arrows: load 20 kN/m, unbalance 200 N/m',
        eye_controls=rrb.EyeControls3D(position=[0.8, 0.6, 2.3], look_target=[0.0, -0.1, 0.0],
                                       eye_up=[0.0, 1.0, 0.0]),
        line_grid=rrb.LineGrid3D(visible=True, spacing=0.25,
                                 plane=rr.components.Plane3D([0.0, 1.0, 0.0], -1.0)))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(gantry, rrb.Horizontal(*polar), row_shares=[3, 2]),
            rrb.Vertical(*motion, row_shares=[2, 5, 4, 4]),
            rrb.Vertical(*loads),
            rrb.Vertical(rrb.TextDocumentView(origin='verdict', name='verdict'),
                         rrb.TextLogView(origin='events', name='events', columns=EVENT_COLUMNS),
                         row_shares=[3, 2]),
            column_shares=[4, 3, 3, 3]),
        rrb.TimePanel(timeline=TIMELINE, state='collapsed'),
        rrb.BlueprintPanel(state='collapsed'), rrb.SelectionPanel(state='collapsed'))


def _polar_title(key):
    if key == 'static':
        return 'static [U / U_per]'
    return f'plane {key[6:]} [U / U_per,{key[6:]}]'


class RunLogger:
    """Log a run to a rerun recording (see the module's description)."""

    def __init__(self, recording, every=1, grade=None, warn_fraction=WARN_FRACTION,
                 evidence=None):
        """
        Log to ``recording`` (a rerun.RecordingStream); arrows every ``every``-th sample.

        ``grade`` (mm/s, default each layout's) and ``warn_fraction`` as the node's.
        ``evidence``: {(layout digest, segment start ns): VerdictOfRecord} of a bag's
        segments (:func:`cvc_balance.bag.identify_run.segment_verdict`), known before the
        replay, so the verdict lane and panel lead with the measured rotor from the start.
        """
        self._evidence = dict(evidence or {})
        self._record = None          # the segment's VerdictOfRecord (None: the layout's)
        self.rec = recording
        self.every = every
        self.grade = grade or None
        self.warn_fraction = warn_fraction
        self._model = self._full = None
        self._pending = None
        self._supports = []
        self._planes = None
        self._count = 0
        self._top_speed = 0.0
        self._drawn_top = 0.0
        self._verdict = None
        self._shown = None            # (level, record) last logged on the lane
        self._unit_fractions = ()     # fractions at 1 rad/s (layouts without a service speed)
        self._level_code = 0
        self._static_range = None      # N, the static weight plot's axis
        self._static_logged = False
        self._time_ns = 0
        self._origin_ns = None        # the run's first stamp: 0 s on the views' timeline
        self._warnings, self._changes = (), {}
        self._cells = False
        self._life = None              # LifeCounters of the bearings in force (None: none)
        self._life_shown = False       # the blueprint has the life plot

    def finish(self):
        """Flush and close the recording."""
        self.rec.flush()
        self.rec.disconnect()

    # -- a layout comes into force -------------------------------------------------

    def layout(self, time_ns, model, segment_start_ns=None):
        """
        Draw the rotor of a layout in force from ``time_ns``, judge it and say so.

        ``time_ns`` None: from the next sample's stamp (the live node before any sample:
        its stamps, not the wall clock, are the time line). ``segment_start_ns``: the log
        time the layout came into force (a bag's segment; the key of ``evidence``).
        """
        if time_ns is None:
            self._pending = model
            return
        self._pending = None
        layout = model.layout
        self._record = self._evidence.get((layout.digest(), segment_start_ns))
        rec = self.rec
        previous = self._model.layout if self._model is not None else None
        planes = plane_keys(layout)
        new = [s.name for s in model.supports if s.name not in self._supports]
        at_rest = support_load_parts(model, np.linspace(0.0, 2 * math.pi, 8, endpoint=False),
                                     0.0, 0.0).static
        lightest = min(float(v.min()) for v in at_rest.values())
        heaviest = max(float(v.max()) for v in at_rest.values())
        shown = self._static_range
        outside = heaviest > 0.0 and (shown is None or lightest < shown[0]
                                      or heaviest > shown[1])
        life = LifeCounters(model.supports, *((self._life.counters, self._life.last)
                                              if self._life is not None else ()))
        self._life = life if life else None
        grown = life and not self._life_shown
        self._life_shown = self._life_shown or bool(life)
        if new or planes != self._planes or outside or grown:
            # The blueprint has a polar view per plane and the static weights' axis.
            self._supports += new
            self._planes = planes
            if outside:
                low, high = 0.0, 1.2 * heaviest
                self._static_range = (low, high) if shown is None else \
                    (min(low, shown[0]), max(high, shown[1]))
            rec.send_blueprint(blueprint(self._supports, planes, self._static_range,
                                         self._cells, self._life_shown))
            self._log_styles(new, planes)
        for name in life.counters:
            colour = SUPPORT_COLOURS[self._supports.index(name) % len(SUPPORT_COLOURS)]
            rec.log(f'plots/life/{name}', rr.SeriesLines(names=[name], colors=[colour],
                                                         widths=[2.0]), static=True)
        self._model = model
        # The verdict is the full model's (replay --tolerance may hand a reduced one).
        self._full = model if model.own_inertia else RotorModel.from_layout(layout)
        self._top_speed = self._drawn_top = 0.0
        self._at(time_ns)
        axis, angle = stator_tilt(layout.gravity)
        rec.log('world/stator', rr.Transform3D(
            rotation=rr.RotationAxisAngle(axis=axis, radians=angle)))
        rec.log('world/stator/ring', rr.LineStrips3D(
            [_circle(STATOR_RING_RADIUS, z) for z in (-0.2, 0.2)], colors=[(150, 150, 150)]))
        rec.log('world/stator/supports', rr.Points3D(
            [[0.0, 0.0, s.z] for s in layout.supports], radii=0.03, colors=[(200, 200, 200)]))
        changes = describe_changes(previous, layout)
        self._draw_rotor(model, changes)
        warnings = layout_warnings(layout)
        moved = '; '.join(f'{name}: {change}' for name, change in changes.items())
        self._time_ns = time_ns
        self._event(f'layout {layout.name} {layout.digest()}'
                    + (f': {moved}' if moved and previous is not None else ''), 'INFO')
        for warning in warnings:
            self._event(f'implausible? {warning}', 'WARN', LEVEL_COLOURS[assessment.WARN])
        self._warnings = warnings
        self._changes = changes if previous is not None else {}
        self._unit_fractions, self._level_code = (), 0
        if layout.balancing.service_speed is None:
            self._unit_fractions = assess_balance(self._full, 1.0, self._grade()).fractions
        self._judge(0.0)

    def _grade(self):
        return self.grade or self._model.layout.balancing.grade

    def _log_styles(self, supports, planes):
        rec = self.rec
        if not self._static_logged:
            self._static_logged = True
            rec.log('world', rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)
            rec.log('world/gravity', rr.Arrows3D(
                origins=[[1.05, 0.35, 0.0]], vectors=[[0.0, -0.3, 0.0]], labels=['g'],
                colors=[(200, 200, 200)]), static=True)
            rec.log('verdict_level', rr.StateConfiguration(
                values=list(LEVEL_COLOURS), labels=list(LEVEL_COLOURS),
                colors=[LEVEL_COLOURS[k] for k in LEVEL_COLOURS]), static=True)
            for path, name, colour in (('plots/speed/omega', 'ω [rad/s]', (80, 200, 255)),
                                       ('plots/speed/alpha', 'α [rad/s²]', (255, 200, 60)),
                                       ('plots/drive_torque', 'drive torque [N m]',
                                        (200, 120, 255)),
                                       ('plots/unbalance/limit', 'limit',
                                        LEVEL_COLOURS[assessment.ERROR])):
                rec.log(path, rr.SeriesLines(names=[name], colors=[colour], widths=[2.0]),
                        static=True)
        for key in planes:
            label = 'static' if key == 'static' else f'plane {key[6:]}'
            # The load cells' (drawn when they can tell) deeper and thicker than the layout's.
            rec.log(f'plots/unbalance/{key}', rr.SeriesLines(
                names=[f'{label}, layout'], colors=[PLANE_COLOURS[key]],
                widths=[2.0]), static=True)
            rec.log(f'plots/unbalance/measured_{key}', rr.SeriesLines(
                names=[f'{label}, measured'],
                colors=[MEASURED_PLANE_COLOURS[key]], widths=[3.0]), static=True)
            rec.log(f'polar/{key}/grid', _polar_grid(), static=True)
            rec.log(f'polar/{key}/grid_labels', _polar_grid_labels(), static=True)
        for name in supports:
            colour = SUPPORT_COLOURS[self._supports.index(name) % len(SUPPORT_COLOURS)]
            for part in ('rotating', 'static'):
                rec.log(f'plots/load_{part}/{name}', rr.SeriesLines(
                    names=[f'{name} [N]'], colors=[colour], widths=[2.0]), static=True)

    def _draw_rotor(self, model, changes):
        layout, rec = model.layout, self.rec
        rec.log('world/stator/rotor/components', rr.Clear(recursive=True))
        smallest = view_resolution(layout)
        labelled = _labelled(layout, changes, [(0.0, 0.0, s.z) for s in layout.supports]
                             + _correction_places(self._full))
        for component in layout.components:
            changed = component.name in changes
            label = None
            if component.name in labelled:
                label = component.name + (f' ({changes[component.name]})' if changed else '')
            rec.log(f'world/stator/rotor/components/{component.name}',
                    _shape(component, CHANGED_COLOUR if changed else COMPONENT_COLOUR,
                           smallest, label))
        rec.log('world/stator/rotor/correction', rr.Clear(recursive=True))

    # -- the verdict ------------------------------------------------------------------

    def _judge(self, top_speed, quiet=False):
        """
        Judge the layout in force at the top speed seen; log the verdict of record.

        The lane, the panel and the drawings are the measured rotor's when the segment's
        load cells can tell (:mod:`cvc_balance.identify.evidence`), else the layout's.
        ``quiet``: only the text and drawings follow (the top speed grew, the level
        did not change).
        """
        verdict = judge_balance(self._full, top_speed, self._grade(), self.warn_fraction)
        old, self._verdict = self._shown, verdict
        record = self._record
        measured = record is not None and record.source == MEASURED
        level = record.level if measured else verdict.level
        self._shown = (level, record if measured else None)
        rec = self.rec
        if not quiet:
            rec.log('verdict_level', rr.StateChange(state=level))
        rec.log('verdict', rr.TextDocument(self._verdict_text(verdict, record),
                                           media_type='text/markdown'))
        if not quiet and (old is None or old != self._shown or top_speed == 0.0):
            if measured:
                said = f'{level}: {record.statement}'
            else:
                a = verdict.assessment
                said = f'{level}: ' + (verdict.words if a is None else
                                       f'G {a.equivalent_grade:.3g} at {a.omega:.4g} rad/s: '
                                       f'{verdict.words} (from the layout)')
            self._event(said, LOG_LEVELS[level], LEVEL_COLOURS[level])
        self._draw_balance(record.measured if measured else verdict)

    def evidence(self, time_ns, of_record):
        """
        Take the live node's verdict of record from ``time_ns`` (ns); log it when it changes.

        A change is a new level or source, or an achieved grade 3 % off the one shown.
        """
        old, self._record = self._record, of_record
        if self._model is None:
            return
        if old is not None and (old.level, old.source) == (of_record.level, of_record.source):
            before, now = old.equivalent_grade, of_record.equivalent_grade
            if before is None or now is None or abs(now - before) <= 0.03 * abs(before):
                return
        self._time_ns = time_ns
        self._at(time_ns)
        self._judge(self._top_speed)

    def _since_start(self, stamp_ns):
        """Return s since the run's first stamp (ns); the first stamp seen is the start."""
        stamp_ns = np.asarray(stamp_ns, np.int64)
        if self._origin_ns is None and stamp_ns.size:
            self._origin_ns = int(stamp_ns.min())
        return (stamp_ns - (self._origin_ns or 0)) * 1e-9

    def _at(self, stamp_ns):
        """Log what follows at the stamp ``stamp_ns`` (ns), on both timelines."""
        self.rec.set_time(TIMELINE, duration=float(self._since_start(stamp_ns)))
        self.rec.set_time(STAMP_TIMELINE, timestamp=stamp_ns * 1e-9)

    def _columns(self, stamp_ns):
        """Return the time columns of samples stamped ``stamp_ns`` (ns): both timelines."""
        stamp_ns = np.asarray(stamp_ns, np.int64)
        return [rr.TimeColumn(TIMELINE, duration=self._since_start(stamp_ns)),
                rr.TimeColumn(STAMP_TIMELINE, timestamp=stamp_ns * 1e-9)]

    def _event(self, text, level, colour=None):
        """Log an events line, its time since the start first (a column would take width)."""
        since = float(self._since_start(self._time_ns))
        self.rec.log('events', rr.TextLog(f'{since:6.2f} s  {text}', level=level,
                                          color=colour))

    def _verdict_text(self, verdict, record=None):
        """
        Return the verdict panel (Markdown): the verdict of record and its source first.

        Measured: the measured rotor's grade and corrections, what the layout expects,
        and where the rotor is not what its layout says. Else the layout's, labelled.
        """
        layout = self._model.layout
        measured = record is not None and record.source == MEASURED
        shown = record.measured if measured else verdict
        level = record.level if measured else verdict.level
        a = shown.assessment
        source = record.source_text if record is not None else 'from the layout'
        lines = [f'## {level}: {shown.words}', '', f'**{source}**', '',
                 f"layout **{layout.name}** (`{layout.digest()}`)", '']
        if measured:
            lines += [record.layout_text, '']
            if record.disagreements:
                lines += [f'**{record.disagreement_text}**', '']
        if a is None:
            lines.append(shown.text)
        else:
            lines += [f'achieved **G {a.equivalent_grade:.3g}** at the {shown.speed_source} '
                      f'{a.omega:.4g} rad/s; U_per {g_mm(a.permissible):,.0f} g mm', '',
                      f'correction masses at r {layout.correction_radius():.3g} m'
                      + (' (for the measured rotor):' if measured else ':')
                      if a.planes else 'no correction planes: the static unbalance is judged',
                      '',
                      '| plane | U [g mm] | angle | / limit | add |',
                      '|---|---:|---:|---:|---|']
            for key, p, allowed, fraction in zip(PLANES, a.planes, a.plane_permissible,
                                                 a.fractions):
                lines.append(f'| {key[6:]} | {g_mm(p.amount):,.0f} | '
                             f'{degrees_360(p.angle):.1f}° | {fraction:.2f} | '
                             f'{_added(p)[4:]} at {degrees_360(p.correction_angle):.1f}° |')
            if not a.planes:
                lines.append(f'| static | {g_mm(a.static_amount):,.0f} | '
                             f'{degrees_360(a.static_angle):.1f}° | {a.fractions[0]:.2f} | |')
        if self._changes:
            lines += ['', 'changed: ' + '; '.join(f'**{name}** {change}'
                                                  for name, change in self._changes.items())]
        if self._warnings:
            lines += ['', '**implausible?**'] + [f'- {w}' for w in self._warnings]
        return '\n'.join(lines)

    def _draw_balance(self, verdict):
        """Correction masses in 3D and the polar diagrams, for the verdict's assessment."""
        a = verdict.assessment
        rec = self.rec
        if a is None:
            return
        places = _correction_places(self._full)
        texts = [f'{key[6:]}: {_added(p)}' for key, p in zip(PLANES, a.planes)]
        if len(places) == 2 and math.dist(*places) <= LABEL_SPACING:
            texts = [' '.join(texts), None]     # one label for both: they would overlap
        for key, plane, allowed, fraction, place, text in zip(
                PLANES, a.planes, a.plane_permissible, a.fractions, places, texts):
            rec.log(f'world/stator/rotor/correction/{key}', rr.LineStrips3D(
                [_circle(plane.correction_radius, plane.z)], colors=[CORRECTION_COLOUR]))
            rec.log(f'world/stator/rotor/correction/{key}/mass', rr.Points3D(
                [place], radii=0.015 + 0.1 * min(plane.correction_mass or 0.0, 1.0),
                colors=[CORRECTION_COLOUR], labels=[text] if text else None))
            self._draw_polar(key, fraction, plane.angle, g_mm(plane.amount), g_mm(allowed),
                             f'{_added(plane)} at '
                             f'{degrees_360(plane.correction_angle):.0f}°, r '
                             f'{plane.correction_radius:.2f} m')
        if not a.planes:
            self._draw_polar('static', a.fractions[0], a.static_angle, g_mm(a.static_amount),
                             g_mm(a.permissible), None)

    def _draw_polar(self, key, fraction, angle, amount, allowed, correction):
        rec = self.rec
        colour = PLANE_COLOURS[key]
        reach = min(fraction, POLAR_REACH)
        c, s = math.cos(angle), math.sin(angle)

        def at(radius, theta):     # rotor-frame polar point drawn with Y up
            return [radius * math.cos(theta), -radius * math.sin(theta)]

        rec.log(f'polar/{key}/limit', rr.LineStrips2D(
            [_ring(1.0)], colors=[LEVEL_COLOURS[assessment.ERROR]], radii=0.012))
        vectors = [[reach * c, -reach * s]]
        colours = [colour]
        if correction is not None:
            vectors.append([-reach * c, reach * s])
            colours.append(CORRECTION_COLOUR)
        rec.log(f'polar/{key}/vectors', rr.Arrows2D(origins=[[0.0, 0.0]] * len(vectors),
                                                    vectors=vectors, colors=colours,
                                                    radii=0.025))
        # Labels apart, in rows of their own above and below the grid (in their colours):
        # the unbalance above, the limit (the red circle's size, which a label on the
        # circle would have printed over) and the correction below; the 0.5 ring's label
        # on the diagonal most across the vectors' line, clear of the angle labels.
        positions = [[0.0, -POLAR_TEXT_ROW - 0.15],    # labels hang below their point
                     [0.0, POLAR_TEXT_ROW]]
        texts = [f'U {amount:,.0f} g mm at {degrees_360(angle):.0f}° = {fraction:.2f}',
                 f'limit (red circle) {allowed:,.0f} g mm']
        shades = [colour, LEVEL_COLOURS[assessment.ERROR]]
        if correction is not None:
            positions.append([0.0, POLAR_TEXT_ROW + POLAR_LINE])
            texts.append(correction)
            shades.append(CORRECTION_COLOUR)
        across = max((math.pi / 4 + k * math.pi / 2 for k in range(4)),
                     key=lambda d: abs(math.sin(d - angle)) - 1e-9 * d)
        positions.append(at(0.5, across + math.pi))
        texts.append('0.5')
        rec.log(f'polar/{key}/labels', rr.Points2D(
            positions, radii=0.0, labels=texts, show_labels=True,
            colors=shades + [(160, 160, 170)]))

    # -- load cells ---------------------------------------------------------------------

    def cells(self, support, stamp_ns, measured_x, predicted_x):
        """
        Plot a support's load cell beside the force the layout predicts there.

        Stator x, N, the cell's fitted zero taken off; both at the cell's stamps (ns).
        """
        if not self._cells:
            self._cells = True
            self.rec.send_blueprint(blueprint(self._supports, self._planes or PLANES,
                                              self._static_range, True, self._life_shown))
        times = self._columns(stamp_ns)
        index = self._supports.index(support) if support in self._supports else 0
        colour = SUPPORT_COLOURS[index % len(SUPPORT_COLOURS)]
        for kind, values in (('measured', measured_x), ('predicted', predicted_x)):
            # Measured in the support's colour, the layout's prediction in white: one plot
            # per support, so no two of its lines share a hue.
            self.rec.log(f'plots/cells/{support}/{kind}', rr.SeriesLines(
                names=['measured' if kind == 'measured' else 'layout\'s prediction'],
                colors=[colour if kind == 'measured' else PREDICTED_COLOUR],
                widths=[1.5 if kind == 'measured' else 2.0]), static=True)
            rr.send_columns(f'plots/cells/{support}/{kind}', indexes=times,
                            columns=rr.Scalars.columns(scalars=np.asarray(values, float)),
                            recording=self.rec)

    def measured(self, time_ns, residual, identified, of_record=None):
        """
        Draw what the cells found, from ``time_ns``, and say it in the events.

        Per plane the residual (measured - declared, a
        :class:`cvc_balance.identify.RotorUnbalance`) on its polar diagram, in the
        diagram's units (fractions of the plane's permissible share), with its 95 % radius.
        ``of_record``: the segment's verdict of record (its layout's permissible shares;
        the event's level: WARN or ERROR when the rotor is not what its layout says).
        """
        verdict = of_record.layout if of_record is not None else self._verdict
        if verdict is None or verdict.assessment is None:
            return
        rec = self.rec
        self._time_ns = time_ns
        self._at(time_ns)
        allowed = verdict.assessment.plane_permissible
        planes = PLANES      # residual.planes is empty without correction planes
        for key, (_, off), share in zip(planes, residual.planes, allowed):
            reach = min(off.amount / share, POLAR_REACH)
            c, s = math.cos(off.angle), math.sin(off.angle)
            rec.log(f'polar/{key}/residual', rr.Arrows2D(
                origins=[[0.0, 0.0]], vectors=[[reach * c, -reach * s]],
                colors=[RESIDUAL_COLOUR], radii=0.02))
            # Its words in a row of their own, under the unbalance's (not at the tip,
            # where they would print over the grid's labels).
            rec.log(f'polar/{key}/residual_label', rr.Points2D(
                [[0.0, -POLAR_TEXT_ROW + 0.08]], radii=0.0, colors=[RESIDUAL_COLOUR],
                labels=[f'cells - layout {g_mm(off.amount):,.0f}±{g_mm(off.ci95):,.0f} g mm '
                        f'{degrees_360(off.angle):.0f}°'],
                show_labels=True))
        if of_record is not None and of_record.disagreements:
            level = assessment.ERROR if of_record.level == assessment.ERROR else assessment.WARN
            self._event(of_record.disagreement_text, LOG_LEVELS[level], LEVEL_COLOURS[level])
            return
        found = '; '.join(f'{key[6:]} {g_mm(v.amount):,.0f} g mm at {degrees_360(v.angle):.0f}°'
                          for key, (_, v) in zip(planes, residual.planes))
        self._event(f'load cells: the rotor agrees with its layout (cells - layout: {found})',
                    'INFO', RESIDUAL_COLOUR)

    # -- samples ----------------------------------------------------------------------

    def sample(self, stamp_ns, angle, omega, alpha, result):
        """Log one sample of the live node (SampleLoads), every ``every``-th one only."""
        self._count += 1
        if self._count % self.every and self._pending is None:
            return
        one = SimpleNamespace(
            support_force={name: np.array([force]) for name, (force, _) in
                           result.supports.items()},
            drive_torque=np.array([result.drive_torque]))
        self.samples(np.array([stamp_ns]), np.array([angle]), np.array([omega]),
                     np.array([alpha]), one, every=1)

    def samples(self, stamp_ns, angle, omega, alpha, result, every=None):
        """Log a block of samples, given as arrays, and the engine's result for them."""
        every = every or self.every
        stamp_ns = np.asarray(stamp_ns)
        if self._pending is not None and len(stamp_ns):
            self.layout(int(stamp_ns[0]), self._pending)
        model, rec = self._model, self.rec
        times = self._columns(stamp_ns)
        n = len(omega)
        scalars = {'plots/speed/omega': omega, 'plots/speed/alpha': alpha,
                   'plots/drive_torque': result.drive_torque,
                   'plots/unbalance/limit': np.ones(n)}
        parts = support_load_parts(model, angle, omega, alpha)
        for name in parts.static:
            scalars[f'plots/load_rotating/{name}'] = parts.rotating[name]
            scalars[f'plots/load_static/{name}'] = parts.static[name]
        top = np.maximum.accumulate(np.maximum(np.abs(omega), self._top_speed))
        fractions = self._fractions(top, n)
        for key, values in zip(self._planes, fractions):
            scalars[f'plots/unbalance/{key}'] = values
        if self._life is not None and n:
            used = self._life.add(np.asarray(stamp_ns, np.int64) * 1e-9, angle, omega,
                                  result.support_force)
            for name, values in used.items():
                scalars[f'plots/life/{name}'] = values
        record = self._record
        if record is not None and record.source == MEASURED and record.measured.assessment:
            for key, fraction in zip(self._planes, record.measured.assessment.fractions):
                scalars[f'plots/unbalance/measured_{key}'] = np.full(n, fraction)
        for path, values in scalars.items():
            rr.send_columns(path, indexes=times,
                            columns=rr.Scalars.columns(scalars=np.asarray(values, float)),
                            recording=rec)
        half = 0.5 * np.asarray(angle, float)
        quaternions = np.zeros((n, 4))
        quaternions[:, 2], quaternions[:, 3] = np.sin(half), np.cos(half)
        rr.send_columns('world/stator/rotor', indexes=times,
                        columns=rr.Transform3D.columns(quaternion=quaternions), recording=rec)
        if n and model.layout.balancing.service_speed is None:
            self._follow_top_speed(stamp_ns, top)
        self._arrows(stamp_ns, omega, result, every)

    def _fractions(self, top, n):
        """Per judged plane, (n,) fractions of its limit; NaN while not judged."""
        verdict = self._verdict
        if self._model.layout.balancing.service_speed is not None:
            return [np.full(n, f) for f in verdict.assessment.fractions]
        with np.errstate(invalid='ignore'):
            return [np.where(top > 0.0, f * top, np.nan) for f in self._unit_fractions]

    def _follow_top_speed(self, stamp_ns, top):
        """
        Without a service speed the verdict is judged at the top speed seen: follow it.

        The level can only rise with the top speed (U_per falls as 1 / omega); it is
        re-judged at each sample where the worst plane's fraction crosses a level.
        """
        worst = max(self._unit_fractions) * top
        code = np.where(top <= 0.0, 0, np.where(worst <= self.warn_fraction, 1,
                                                np.where(worst <= 1.0, 2, 3)))
        steps = np.nonzero(np.diff(np.concatenate([[self._level_code], code])))[0]
        for k in steps.tolist():
            self._time_ns = int(stamp_ns[k])
            self._at(self._time_ns)
            self._judge(float(top[k]))
        self._level_code = int(code[-1])
        self._top_speed = float(top[-1])
        # The verdict text and the polar arrows follow the top speed in 3 % steps.
        while True:
            k = int(np.searchsorted(top, max(1.03 * self._drawn_top, 1e-300), side='left'))
            if k >= len(top):
                break
            self._drawn_top = float(top[k])
            self._time_ns = int(stamp_ns[k])
            self._at(self._time_ns)
            self._judge(self._drawn_top, quiet=True)

    def _arrows(self, stamp_ns, omega, result, every):
        """Load and unbalance arrows for a subset of the samples (a viewer need not draw all)."""
        model, rec = self._model, self.rec
        static = static_unbalance(model)
        com = [0.0, 0.0, model.s_z / model.mass]
        origins = [[0.0, 0.0, s.z] for s in model.supports]
        for k in range(0, len(omega), every):
            self._at(int(stamp_ns[k]))
            forces = [result.support_force[s.name][k] for s in model.supports]
            rec.log('world/stator/loads', rr.Arrows3D(
                origins=origins, vectors=[_arrow(f, NEWTONS_PER_METRE) for f in forces],
                colors=[LOAD_COLOUR], radii=0.012))
            # The static unbalance's centrifugal force, U omega^2, turns with the rotor.
            force, _ = unbalance_wrench(static, (0.0, 0.0), float(omega[k]))
            size = math.hypot(force[0], force[1])
            rec.log('world/stator/rotor/unbalance_force', rr.Arrows3D(
                origins=[com], vectors=[_arrow(force, UNBALANCE_NEWTONS_PER_METRE)],
                colors=[UNBALANCE_COLOUR], radii=0.012,
                labels=[f'U ω² {size:.0f} N'] if size > 1.0 else None))


def _arrow(force, newtons_per_metre):
    """Return the arrow (m) of a force (N), at most LONGEST_ARROW long."""
    vector = np.asarray(force, float) / newtons_per_metre
    length = float(np.linalg.norm(vector))
    if length > LONGEST_ARROW:
        vector = vector * (LONGEST_ARROW / length)
    return vector.tolist()


def describe_changes(previous, layout):
    """
    {component name: what changed} between two layouts, for people.

    New components say 'added'; removed ones are listed under their name as
    'removed'. Empty when ``previous`` is None.
    """
    if previous is None:
        return {}
    before = {c.name: c for c in previous.components}
    changes = {}
    for c in layout.components:
        old = before.pop(c.name, None)
        if old is None:
            changes[c.name] = 'added'
            continue
        said = []
        for field, unit, scale in (('mass', 'kg', 1.0), ('radius', 'm', 1.0),
                                   ('angle', 'deg', 180.0 / math.pi), ('z', 'm', 1.0)):
            a, b = getattr(old, field), getattr(c, field)
            if a != b:
                said.append(f'{field} {a * scale:.6g} → {b * scale:.6g} {unit}')
        if old.shape != c.shape or old.inertia != c.inertia:
            said.append('shape or inertia')
        if said:
            changes[c.name] = ', '.join(said)
    for name in before:
        changes[name] = 'removed'
    return changes


def _labelled(layout, changes, reserved=()):
    """
    Names of the components whose 3D label fits: changed ones first, then by m R.

    A label is left out when its centre of mass is within LABEL_SPACING of one
    already labelled or of a ``reserved`` point (m, rotor frame: where the load
    arrows start and the correction masses sit).
    """
    taken = list(reserved)
    order = sorted(layout.components, key=lambda c: (c.name not in changes, -c.mass * c.radius))
    names = set()
    for c in order:
        here = (c.radius * math.cos(c.angle), c.radius * math.sin(c.angle), c.z)
        if all(math.dist(here, other) > LABEL_SPACING for other in taken):
            names.add(c.name)
            taken.append(here)
    return names


def _correction_places(model):
    """Where the correction masses go, (x, y, z) m in the rotor frame (none without planes)."""
    layout = model.layout
    planes = layout.correction_planes()
    if planes is None:
        return []
    return [(p.correction_radius * math.cos(p.correction_angle),
             p.correction_radius * math.sin(p.correction_angle), p.z)
            for p in plane_unbalances(model, *planes, layout.correction_radius())]


def _circle(radius, z, points=97, centre=(0.0, 0.0, 0.0)):
    angles = np.linspace(0.0, 2 * math.pi, points)
    return np.stack([centre[0] + radius * np.cos(angles), centre[1] + radius * np.sin(angles),
                     np.full(points, z)], axis=1)


def _ring(radius, points=97):
    angles = np.linspace(0.0, 2 * math.pi, points)
    return np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)


def _polar_grid():
    """Rings at 0.5 and 1.4, spokes every 30 deg; the 0 deg spoke (rotor X) brighter."""
    strips = [_ring(0.5), _ring(1.4)]
    colours = [GRID_COLOUR, GRID_COLOUR]
    for k in range(12):
        theta = k * math.pi / 6
        strips.append([[0.0, 0.0], [1.4 * math.cos(theta), -1.4 * math.sin(theta)]])
        colours.append((220, 220, 220) if k == 0 else GRID_COLOUR)
    return rr.LineStrips2D(strips, colors=colours, radii=[0.006] * 2 + [0.012] + [0.004] * 11)


def _polar_grid_labels():
    """Angle labels outside the grid, counter-clockwise; 0 deg names rotor X."""
    angles = (0, 90, 180, 270)
    positions = [[1.6 * math.cos(math.radians(a)), -1.6 * math.sin(math.radians(a))]
                 for a in angles]
    labels = ['0°', '90°', '180°', '270°']
    return rr.Points2D(positions, radii=0.0, labels=labels, show_labels=True,
                       colors=[(220, 220, 220)] + [(160, 160, 170)] * 3)


def _added(plane):
    """Say what a plane's correction is: 'add 129 g', or that there is no radius for one."""
    if plane.correction_mass is None:
        return 'add nothing: no correction radius'
    return f'add {plane.correction_mass * 1e3:.0f} g'


def view_resolution(layout):
    """
    Smallest shape (m) the 3D view resolves: two pixels of the whole rotor's width.

    Drawing a shape below it as a solid costs the viewer a mesh and shows nothing
    more than a point does.
    """
    reach = max([STATOR_RING_RADIUS] + [
        c.radius + (c.shape.extent / 2 if c.shape is not None else 0.0)
        for c in layout.components])
    return 2.0 * (2.0 * reach) / VIEW_PIXELS


def _shape(component, colour, smallest=0.0, label=None):
    """Return a component's shape in the rotor frame at (R, theta, z), for rerun."""
    c, s = math.cos(component.angle), math.sin(component.angle)
    centre = [component.radius * c, component.radius * s, component.z]
    turn = rr.RotationAxisAngle(axis=[0, 0, 1], radians=component.angle)
    shape = component.shape
    labels = [label] if label else None
    if shape is None or shape.type == 'point' or shape.extent < smallest:
        return rr.Points3D([centre], radii=0.02, colors=[colour], labels=labels)
    if shape.type == 'box':
        return rr.Boxes3D(centers=[centre], half_sizes=[[v / 2 for v in shape.size]],
                          rotation_axis_angles=[turn], colors=[colour], labels=labels,
                          fill_mode='solid')
    if shape.type == 'sphere':
        return rr.Ellipsoids3D(centers=[centre], half_sizes=[[shape.radius] * 3],
                               colors=[colour], labels=labels, fill_mode='solid')
    if shape.type == 'tube' and shape.axis == 'axial':
        # A hollow drum drawn solid would hide everything inside it: its four rims.
        rims = [_circle(r, component.z + end * shape.length / 2, centre=centre)
                for r in (shape.inner_radius, shape.outer_radius) for end in (-1, 1)]
        return rr.LineStrips3D(rims, colors=[colour], labels=[label] + [''] * 3 if label
                               else None)
    radius = shape.outer_radius if shape.type == 'tube' else shape.radius
    # rerun's cylinders lie along Z; radial and tangential axes are turned onto x, y.
    axis = {'axial': None, 'radial': [-s, c, 0.0], 'tangential': [c, s, 0.0]}[shape.axis]
    rotation = [rr.RotationAxisAngle(axis=axis, radians=math.pi / 2)] if axis else None
    return rr.Cylinders3D(centers=[centre], lengths=[shape.length], radii=[radius],
                          rotation_axis_angles=rotation, colors=[colour], labels=labels,
                          fill_mode='solid')


def open_recording(mode, target='', name='cvc_balance'):
    """
    Open a rerun recording: 'save' to a file, 'connect' to a viewer, or 'spawn' one.

    ``target`` is the .rrd path (save) or the viewer's URL (connect). No usage data is
    sent from the SDK; a spawned viewer keeps its own analytics setting
    (``rerun analytics disable``).
    """
    import os
    os.environ.setdefault('RERUN_ANALYTICS', 'false')
    recording = rr.RecordingStream('cvc_balance', recording_id=str(name))
    if mode == 'save':
        recording.save(str(target or 'run.rrd'))
    elif mode == 'connect':
        recording.connect_grpc(target or None)
    elif mode == 'spawn':
        recording.spawn()
    else:
        raise ValueError(f"rerun mode must be save, connect or spawn, got {mode!r}")
    return recording
