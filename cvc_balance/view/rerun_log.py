"""
The rerun view of a run: the turning gantry, its loads and its unbalance.

One logger for both paths (the live node and ``cvc-balance view`` of a bag). What it
logs, on the timeline ``time`` (the samples' stamps):

* ``world``: the stator ring and supports; ``world/rotor`` turning with q; each
  component as its shape at (R, theta, z), coloured by its share of the static
  unbalance (blue: none, red: the largest); the correction planes and where the
  correction masses go; arrows for the load at each support and the unbalance force.
* ``plots``: omega, alpha, drive torque, each support's load (stator-frame components
  and magnitude), the unbalance per plane against the grade's limit at the current speed.
* ``polar/<plane>``: the unbalance vector per correction plane with its tolerance circle.
* ``events``: layout changes; ``verdict``: the grade verdict.

Units: SI in the 3D view (m; arrows scaled, see ``NEWTONS_PER_METRE``), g mm and degrees
where people read them. The rerun SDK is imported here only (an adapter).
"""

import math
from types import SimpleNamespace

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from cvc_balance.physics.assessment import assess_balance
from cvc_balance.physics.iso21940 import permissible_unbalance
from cvc_balance.physics.unbalance import static_unbalance, unbalance_wrench

TIMELINE = 'time'
NEWTONS_PER_METRE = 20000.0
"""Support load arrows: 20 kN per metre of arrow."""
UNBALANCE_NEWTONS_PER_METRE = 200.0
"""Unbalance force arrow: 200 N per metre (a balanced gantry's is tens of newtons)."""
PLANES = ('plane_I', 'plane_II')
STATOR_RING_RADIUS = 0.85      # m, drawn for orientation
VIEW_PIXELS = 500
"""Pixels across the rotor in a typical 3D view: a shape under two of them is a point."""


def blueprint(support_names):
    """Arrange the views: 3D left, plots in the middle, polar and text right."""
    plots = [rrb.TimeSeriesView(origin='plots/speed', name='omega, alpha'),
             rrb.TimeSeriesView(origin='plots/drive_torque', name='drive torque'),
             rrb.TimeSeriesView(origin='plots/unbalance', name='unbalance vs limit')]
    plots += [rrb.TimeSeriesView(origin=f'plots/supports/{name}', name=f'{name} load')
              for name in support_names]
    return rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial3DView(origin='world', name='gantry'),
        rrb.Vertical(*plots),
        rrb.Vertical(rrb.Spatial2DView(origin='polar', name='unbalance per plane (g mm)'),
                     rrb.TextDocumentView(origin='verdict', name='verdict'),
                     rrb.TextLogView(origin='events', name='events')),
        column_shares=[3, 3, 2]))


class RunLogger:
    """Log a run to a rerun recording (see the module's description)."""

    def __init__(self, recording, every=1, service_speed=None):
        """Log to ``recording`` (a rerun.RecordingStream); arrows every ``every``-th sample."""
        self.rec = recording
        self.every = every
        self.service_speed = service_speed
        self._model = None
        self._planes = ()
        self._supports = []
        self._count = 0

    def finish(self):
        """Flush and close the recording."""
        self.rec.flush()
        self.rec.disconnect()

    def layout(self, time_ns, model):
        """Draw the rotor of a layout in force from ``time_ns``, and say so."""
        layout = model.layout
        new = [s.name for s in model.supports if s.name not in self._supports]
        if new:   # the blueprint has a plot per support: resend it when supports appear
            self._supports += new
            self.rec.send_blueprint(blueprint(self._supports))
        self._model = model
        rec = self.rec
        rec.set_time(TIMELINE, timestamp=time_ns * 1e-9)
        rec.log('world/stator/ring',
                rr.LineStrips3D([_circle(STATOR_RING_RADIUS, 0.0)], colors=[(150, 150, 150)]))
        rec.log('world/stator/supports', rr.Points3D(
            [[0.0, 0.0, s.z] for s in layout.supports], radii=0.03,
            labels=[s.name for s in layout.supports], colors=[(60, 60, 60)]))
        shares = [c.mass * c.radius for c in layout.components]
        top = max(shares) or 1.0
        rec.log('world/rotor/components', rr.Clear(recursive=True))
        smallest = view_resolution(layout)
        for component, share in zip(layout.components, shares):
            rec.log(f'world/rotor/components/{component.name}',
                    _shape(component, _colour(share / top), smallest))
        speed = self.service_speed or layout.balancing.service_speed or 1.0
        assessment = assess_balance(model, speed)
        self._planes = assessment.planes
        for label, plane, allowed in zip(PLANES, assessment.planes,
                                         assessment.plane_permissible):
            radius = plane.correction_radius
            rec.log(f'world/rotor/correction/{label}', rr.LineStrips3D(
                [_circle(radius, plane.z)], colors=[(120, 200, 120)]))
            rec.log(f'world/rotor/correction/{label}/mass', rr.Points3D(
                [[radius * math.cos(plane.correction_angle),
                  radius * math.sin(plane.correction_angle), plane.z]],
                radii=0.02 + 0.2 * min(plane.correction_mass, 1.0), colors=[(40, 160, 40)],
                labels=[f'{plane.correction_mass * 1e3:.0f} g']))
            rec.log(f'polar/{label}/unbalance', rr.Arrows2D(
                origins=[[0.0, 0.0]], vectors=[[v * 1e6 for v in plane.vector]],
                labels=[f'{label}: {plane.amount * 1e6:.0f} g mm at '
                        f'{math.degrees(plane.angle):.1f} deg']))
            rec.log(f'polar/{label}/tolerance', rr.LineStrips2D(
                [[(allowed * 1e6 * math.cos(a), allowed * 1e6 * math.sin(a))
                  for a in np.linspace(0.0, 2 * math.pi, 65)]], colors=[(200, 60, 60)]))
        verdict = 'WITHIN' if assessment.within_grade else 'OUT OF'
        rec.log('verdict', rr.TextDocument(
            f'# {layout.name}\n\ndigest `{layout.digest()}`\n\nachieved G '
            f'{assessment.equivalent_grade:.3g} at {speed:.4g} rad/s: **{verdict} G '
            f'{assessment.grade:g}**\n\n' + '\n'.join(
                f'- {label}: {p.amount * 1e6:.0f} g mm at {math.degrees(p.angle):.1f} deg; '
                f'correct with {p.correction_mass * 1e3:.0f} g at '
                f'{math.degrees(p.correction_angle):.1f} deg'
                for label, p in zip(PLANES, assessment.planes)), media_type='text/markdown'))
        rec.log('events', rr.TextLog(f"layout '{layout.name}' ({layout.digest()}) in force",
                                     level='INFO'))

    def sample(self, stamp_ns, angle, omega, alpha, result):
        """Log one sample of the live node (SampleLoads), every ``every``-th one only."""
        self._count += 1
        if self._count % self.every:
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
        model, rec = self._model, self.rec
        times = rr.TimeColumn(TIMELINE, timestamp=np.asarray(stamp_ns) * 1e-9)
        scalars = {'plots/speed/omega': omega, 'plots/speed/alpha': alpha,
                   'plots/drive_torque': result.drive_torque}
        for name, force in result.support_force.items():
            for i, axis in enumerate('xyz'):
                scalars[f'plots/supports/{name}/{axis}'] = force[:, i]
            scalars[f'plots/supports/{name}/magnitude'] = np.linalg.norm(force, axis=1)
        speed = np.abs(omega)
        service = self.service_speed or model.layout.balancing.service_speed or 0.0
        # The limit grows as 1 / omega: drawn from a fifth of the service speed on.
        shown = speed > max(0.2 * service, 1.0)
        for label, plane in zip(PLANES, self._planes):
            scalars[f'plots/unbalance/{label}'] = np.full(len(omega), plane.amount * 1e6)
            with np.errstate(divide='ignore'):
                limit = permissible_unbalance(model.layout.balancing.grade, model.mass,
                                              speed) * 1e6
            scalars[f'plots/unbalance/{label}_limit'] = np.where(shown, limit, np.nan)
        for path, values in scalars.items():
            rr.send_columns(path, indexes=[times],
                            columns=rr.Scalars.columns(scalars=np.asarray(values, float)),
                            recording=rec)
        rr.send_columns('world/rotor', indexes=[times], columns=rr.Transform3D.columns(
            rotation_axis_angle=[rr.RotationAxisAngle(axis=[0, 0, 1], radians=float(q))
                                 for q in angle]), recording=rec)
        # Arrows: a subset of the samples (a viewer need not draw them all).
        static = static_unbalance(model)
        for k in range(0, len(omega), every):
            rec.set_time(TIMELINE, timestamp=stamp_ns[k] * 1e-9)
            origins = [[0.0, 0.0, s.z] for s in model.supports]
            vectors = [list(result.support_force[s.name][k] / NEWTONS_PER_METRE)
                       for s in model.supports]
            rec.log('world/stator/loads',
                    rr.Arrows3D(origins=origins, vectors=vectors, colors=[(220, 120, 0)]))
            # The static unbalance's centrifugal force, U omega^2, turns with the rotor.
            force, _ = unbalance_wrench(static, (0.0, 0.0), float(omega[k]))
            rec.log('world/rotor/unbalance_force', rr.Arrows3D(
                origins=[[0.0, 0.0, model.s_z / model.mass]],
                vectors=[[f / UNBALANCE_NEWTONS_PER_METRE for f in force]],
                colors=[(230, 30, 30)]))


def _circle(radius, z, points=97, centre=(0.0, 0.0, 0.0)):
    angles = np.linspace(0.0, 2 * math.pi, points)
    return np.stack([centre[0] + radius * np.cos(angles), centre[1] + radius * np.sin(angles),
                     np.full(points, z)], axis=1)


def _colour(share):
    share = min(max(share, 0.0), 1.0)
    return (int(60 + 195 * share), 80, int(255 - 195 * share))


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


def _shape(component, colour, smallest=0.0):
    """Return a component's shape in the rotor frame at (R, theta, z), for rerun."""
    c, s = math.cos(component.angle), math.sin(component.angle)
    centre = [component.radius * c, component.radius * s, component.z]
    turn = rr.RotationAxisAngle(axis=[0, 0, 1], radians=component.angle)
    shape = component.shape
    label = [component.name]
    if shape is None or shape.type == 'point' or shape.extent < smallest:
        return rr.Points3D([centre], radii=0.02, colors=[colour], labels=label)
    if shape.type == 'box':
        return rr.Boxes3D(centers=[centre], half_sizes=[[v / 2 for v in shape.size]],
                          rotation_axis_angles=[turn], colors=[colour], labels=label,
                          fill_mode='solid')
    if shape.type == 'sphere':
        return rr.Ellipsoids3D(centers=[centre], half_sizes=[[shape.radius] * 3],
                               colors=[colour], labels=label, fill_mode='solid')
    if shape.type == 'tube' and shape.axis == 'axial':
        # A hollow drum drawn solid would hide everything inside it: its four rims.
        rims = [_circle(r, component.z + end * shape.length / 2, centre=centre)
                for r in (shape.inner_radius, shape.outer_radius) for end in (-1, 1)]
        return rr.LineStrips3D(rims, colors=[colour], labels=label * 4)
    radius = shape.outer_radius if shape.type == 'tube' else shape.radius
    # rerun's cylinders lie along Z; radial and tangential axes are turned onto x, y.
    axis = {'axial': None, 'radial': [-s, c, 0.0], 'tangential': [c, s, 0.0]}[shape.axis]
    rotation = [rr.RotationAxisAngle(axis=axis, radians=math.pi / 2)] if axis else None
    return rr.Cylinders3D(centers=[centre], lengths=[shape.length], radii=[radius],
                          rotation_axis_angles=rotation, colors=[colour], labels=label,
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
