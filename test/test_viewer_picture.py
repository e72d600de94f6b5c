"""
The docs' picture, rendered headless by rerun's own viewer: every panel shows its data.

``./dev.sh pictures viewer`` makes docs/viewer.png this way: the loose-bracket bag's .rrd
(load cells: the measured verdict leads), the time cursor put 6.5 s after the first sample
(the rotor out of grade by its cells while its layout says OK). Here the same viewer is
asked for each view's own picture, and the pixels are read: every plot has its series'
colours, spread over the time axis (data across the run) and over the height (an axis
fitted to the data: the -1..1 axis of an empty or unfitted plot would show the lines
nowhere or as a sliver), a legend with a dot for every series (a legend taller than its
plot drops entries), at least two tick labels on each axis (a scale, not a lone 0); the
time reads seconds since the run's start; the verdict lane is red (the cells' verdict);
the polar views have their limit circle, unbalance and correction vectors.

Needs a Vulkan adapter: Mesa's lavapipe from Debian's mesa-vulkan-drivers and libvulkan1,
which ``./dev.sh test`` installs when it runs as root with apt-get. Skipped, saying so,
only where they are missing and the viewer finds no adapter.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import numpy as np
import pytest
from scipy import ndimage

from cvc_balance.view import rerun_log

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'loose_bracket.mcap'
AT = 6.5


def debian_vulkan_installed():
    dpkg = shutil.which('dpkg')
    return dpkg is not None and subprocess.run(
        [dpkg, '-s', 'mesa-vulkan-drivers', 'libvulkan1'], capture_output=True).returncode == 0


@pytest.fixture(scope='module')
def pictures(tmp_path_factory):
    from cvc_balance.view.screenshot import HeadlessViewer, ViewerError
    rrd = tmp_path_factory.mktemp('picture') / 'run.rrd'
    made = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'view',
                           str(BAG), '-o', str(rrd)],
                          capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    try:
        viewer = HeadlessViewer(rrd)
    except ViewerError as error:
        if not debian_vulkan_installed() and 'adapter' in str(error).lower():
            pytest.skip('no Vulkan adapter for rerun\'s headless viewer: install '
                        'mesa-vulkan-drivers and libvulkan1 (./dev.sh test does, as root '
                        f'with apt-get): {error}')
        raise
    with viewer:
        start, end = viewer.timeline()
        cursor = viewer.at(AT)
        whole = viewer.screenshot()
        views = {}
        for view in viewer.views():
            # The whole picture has settled: a view's own needs two frames alike.
            views[view.name] = (view.view_class, view.reports,
                                viewer.screenshot(view.view_id, settle=0.0, frames=2))
        state = viewer.client.get_state()
    try:       # the viewer's process group (the rerun script and its binary) has gone
        os.killpg(viewer.process.pid, 0)
        left_running = True
    except ProcessLookupError:
        left_running = False
    return {'start': start, 'end': end, 'cursor': cursor, 'whole': whole, 'views': views,
            'current': state.recordings[0].current_time, 'left_running': left_running,
            'timelines': {t.name: t for t in state.recordings[0].timelines}}


def colour_pixels(image, colour, distance=45.0):
    """Boolean mask of pixels within ``distance`` (RGB) of ``colour``."""
    return np.linalg.norm(image.astype(float) - np.array(colour, float), axis=2) <= distance


def saturated(image):
    """Pixels of a colour (not the grey, white and black of axes, text and the cursor)."""
    image = image.astype(int)
    return (image.max(axis=2) - image.min(axis=2) > 80) & (image.max(axis=2) > 110)


def by_class(pictures, kind):
    return {name: view for name, view in pictures['views'].items() if view[0] == kind}


def first_motion_stamp_ns():
    """Return the bag's first joint state stamp, by the mcap library (a second reader)."""
    from mcap_ros2.decoder import DecoderFactory
    from mcap.reader import make_reader
    with open(BAG, 'rb') as stream:
        for _, _, _, message in make_reader(stream, decoder_factories=[DecoderFactory()]) \
                .iter_decoded_messages(topics=['/joint_states']):
            return message.header.stamp.sec * 10**9 + message.header.stamp.nanosec


def test_the_time_reads_seconds_since_the_run_started(pictures):
    """Not 1970-01-01: the bag's stamps start 1 s after the epoch; the views count from 0."""
    timelines = pictures['timelines']
    shown = timelines[rerun_log.TIMELINE]
    assert shown.time_type == 'duration'
    stamps = timelines[rerun_log.STAMP_TIMELINE]
    first = first_motion_stamp_ns()
    assert first == 1_000_000_000
    assert (shown.start, shown.end) == (0, stamps.end - first)
    assert pictures['cursor'] == round(AT * 1e9) == pictures['current']
    assert pictures['whole'].shape[:2] == (900, 1600)


def test_the_viewer_is_stopped_with_its_child(pictures):
    assert not pictures['left_running']


def test_the_views_are_all_there_and_healthy(pictures):
    kinds = sorted(view[0] for view in pictures['views'].values())
    assert kinds == sorted(['3D', '2D', '2D', 'StateTimeline', 'TextDocument', 'TextLog']
                           + ['TimeSeries'] * len(SERIES)), kinds
    for name, (_, reports, _) in pictures['views'].items():
        assert not reports, (name, reports)


SERIES = {   # a word of each plot's name: the colours of its series, each in its legend
    'unbalance per plane': [rerun_log.LEVEL_COLOURS['ERROR'],
                            rerun_log.PLANE_COLOURS['plane_I'],
                            rerun_log.PLANE_COLOURS['plane_II'],
                            rerun_log.MEASURED_PLANE_COLOURS['plane_I'],
                            rerun_log.MEASURED_PLANE_COLOURS['plane_II']],
    'speed ω': [(80, 200, 255), (255, 200, 60)],
    'drive torque': [(200, 120, 255)],
    'rotating load': list(rerun_log.SUPPORT_COLOURS[:2]),
    'static weight': list(rerun_log.SUPPORT_COLOURS[:2]),
    'front load cell': [rerun_log.SUPPORT_COLOURS[0], rerun_log.PREDICTED_COLOUR],
    'rear load cell': [rerun_log.SUPPORT_COLOURS[1], rerun_log.PREDICTED_COLOUR],
}


def plot(pictures, word):
    (image,) = [view[2] for name, view in by_class(pictures, 'TimeSeries').items()
                if word in name]
    return image


def test_every_plot_shows_its_data_on_a_fitted_axis(pictures):
    assert len(by_class(pictures, 'TimeSeries')) == len(SERIES)
    for word, colours in SERIES.items():
        image = plot(pictures, word)
        height, width = image.shape[:2]
        for colour in colours:
            assert colour_pixels(image, colour).sum() >= 40, (word, colour)
        data = saturated(image)
        columns = np.nonzero(data.any(axis=0))[0]
        rows = np.nonzero(data.any(axis=1))[0]
        # Across the run's time axis (the legend alone covers under a fifth of it) ...
        assert len(columns) >= 0.6 * width, (word, len(columns), width)
        # ... and over the height: the axis fits the data, not -1..1.
        assert rows.max() - rows.min() >= 0.4 * height, (word, rows.min(), rows.max())


def legend_dots(image, colour):
    """(row, column) of the legend's dots of ``colour``: blobs 5-12 pixels across."""
    labels, _ = ndimage.label(colour_pixels(image, colour, 30.0))
    return [(s[0].start, s[1].start) for s in ndimage.find_objects(labels)
            if 5 <= s[0].stop - s[0].start <= 12 and 5 <= s[1].stop - s[1].start <= 12]


def test_every_legend_lists_every_series(pictures):
    """A dot per series, one above the other in one column: none dropped for want of room."""
    for word, colours in SERIES.items():
        image = plot(pictures, word)
        dots = [legend_dots(image, colour) for colour in colours]
        assert all(dots), (word, [c for c, d in zip(colours, dots) if not d])
        column = int(np.median([c for found in dots for _, c in found]))
        rows = sorted(min(r for r, c in found if abs(c - column) <= 2) for found in dots)
        assert len(rows) == len(colours) and np.all(np.diff(rows) >= 15), (word, rows)


def text_marks(mask, gap=8, least=4):
    """Return the runs of True (a label's glyphs, ``gap`` apart at most), ``least`` long."""
    found = np.nonzero(mask)[0]
    runs = []
    for k in found.tolist():
        if runs and k - runs[-1][1] <= gap:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    return [run for run in runs if run[1] - run[0] + 1 >= least]


def grey_text(image):
    image = image.astype(int)
    return (image.max(axis=2) - image.min(axis=2) < 30) & (image.min(axis=2) > 110)


def test_every_axis_has_a_scale(pictures):
    """
    At least two tick labels on each axis of each plot (the drive torque had only its 0).

    The y labels are the grey text left of the data (the series start at the run's start,
    the plot's left edge); the x labels the grey text under it (the time cursor's one-pixel
    line is not a label).
    """
    for word in SERIES:
        image = plot(pictures, word)
        height = image.shape[0]
        left = int(np.nonzero(saturated(image).any(axis=0))[0].min())
        y_labels = text_marks(grey_text(image[:height - 18, :left - 1]).any(axis=1), gap=2)
        x_labels = text_marks(grey_text(image[height - 16:, left:]).any(axis=0))
        assert len(y_labels) >= 2, (word, y_labels)
        assert len(x_labels) >= 2, (word, x_labels)
    torque = plot(pictures, 'drive torque')
    left = int(np.nonzero(saturated(torque).any(axis=0))[0].min())
    assert len(text_marks(grey_text(torque[:-18, :left - 1]).any(axis=1), gap=2)) >= 4


def lab(rgb):
    """CIELAB (D65) of an sRGB colour: the distance people see between colours."""
    c = np.asarray(rgb, float) / 255.0
    c = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722],
                    [0.0193, 0.1192, 0.9505]]) @ c / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def test_no_two_series_of_a_plot_look_alike():
    """CIE76 colour difference of at least 30 between any two series sharing a plot."""
    for word, colours in SERIES.items():
        for k, a in enumerate(colours):
            for b in colours[k + 1:]:
                assert np.linalg.norm(lab(a) - lab(b)) >= 30.0, (word, a, b)


def test_the_measured_verdict_leads_the_lane(pictures):
    """Red throughout: the cells see the bracket from the start (the layout alone: green)."""
    (image,) = [view[2] for view in by_class(pictures, 'StateTimeline').values()]
    r, g, b = (image[:, :, i].astype(int) for i in range(3))
    green = (g > r + 50) & (g > b + 40)       # the lanes are drawn a shade darker
    red = (r > g + 80) & (r > b + 80)
    assert red.sum() > 5000 and green.sum() == 0, (green.sum(), red.sum())
    columns = np.nonzero(red.any(axis=0))[0]
    assert columns.max() - columns.min() >= 0.9 * image.shape[1]


def test_the_polar_views_draw_limit_unbalance_and_correction(pictures):
    polar = by_class(pictures, '2D')
    assert len(polar) == 2
    for name, (_, _, image) in polar.items():
        key = 'plane_I' if name.startswith('plane I ') else 'plane_II'
        for colour in (rerun_log.LEVEL_COLOURS['ERROR'], rerun_log.PLANE_COLOURS[key],
                       rerun_log.CORRECTION_COLOUR, rerun_log.RESIDUAL_COLOUR):
            assert colour_pixels(image, colour).sum() >= 100, (name, colour)


def test_the_3d_view_draws_the_loads_and_corrections(pictures):
    (image,) = [view[2] for view in by_class(pictures, '3D').values()]
    assert colour_pixels(image, rerun_log.COMPONENT_COLOUR).sum() >= 3000
    assert colour_pixels(image, rerun_log.LOAD_COLOUR).sum() >= 50
    assert colour_pixels(image, rerun_log.CORRECTION_COLOUR).sum() >= 200
