"""
The README's picture, rendered headless by rerun's own viewer: every panel shows its data.

``./dev.sh screenshot`` makes docs/viewer.png this way: the tube-swap bag's .rrd, the time
cursor put 6.5 s after the first sample (after the swap, at service speed). Here the same
viewer is asked for each view's own picture, and the pixels are read: every plot has its
series' colours, spread over the time axis (data across the run) and over the height (an
axis fitted to the data: the -1..1 axis of an empty or unfitted plot would show the lines
nowhere or as a sliver); the verdict lanes are green then red; the polar views have their
limit circle, unbalance and correction vectors; the 3D view highlights the swapped tube.

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

from cvc_balance.view import rerun_log

ROOT = Path(__file__).resolve().parents[1]
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
                           str(ROOT / 'bags' / 'spin_up_tube_swap.mcap'), '-o', str(rrd)],
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
        start, _ = viewer.timeline()
        cursor = viewer.at(AT)
        whole = viewer.screenshot()
        views = {}
        for view in viewer.views():
            # The whole picture has settled: a view's own needs two frames alike.
            views[view.name] = (view.view_class, view.reports,
                                viewer.screenshot(view.view_id, settle=0.0))
        state = viewer.client.get_state()
    try:       # the viewer's process group (the rerun script and its binary) has gone
        os.killpg(viewer.process.pid, 0)
        left_running = True
    except ProcessLookupError:
        left_running = False
    return {'start': start, 'cursor': cursor, 'whole': whole, 'views': views,
            'current': state.recordings[0].current_time, 'left_running': left_running}


def colour_pixels(image, colour, distance=45.0):
    """Boolean mask of pixels within ``distance`` (RGB) of ``colour``."""
    return np.linalg.norm(image.astype(float) - np.array(colour, float), axis=2) <= distance


def saturated(image):
    """Pixels of a colour (not the grey, white and black of axes, text and the cursor)."""
    image = image.astype(int)
    return (image.max(axis=2) - image.min(axis=2) > 80) & (image.max(axis=2) > 110)


def by_class(pictures, kind):
    return {name: view for name, view in pictures['views'].items() if view[0] == kind}


def test_the_cursor_is_where_the_story_is(pictures):
    assert pictures['cursor'] == pictures['start'] + round(AT * 1e9)
    assert pictures['current'] == pictures['cursor']
    assert pictures['whole'].shape[:2] == (900, 1600)


def test_the_viewer_is_stopped_with_its_child(pictures):
    assert not pictures['left_running']


def test_the_views_are_all_there_and_healthy(pictures):
    kinds = sorted(view[0] for view in pictures['views'].values())
    assert kinds == sorted(['3D', '2D', '2D', 'StateTimeline', 'TextDocument', 'TextLog']
                           + ['TimeSeries'] * 5), kinds
    for name, (_, reports, _) in pictures['views'].items():
        assert not reports, (name, reports)


SERIES = {   # a word of each plot's name: the colours of its series
    'unbalance per plane': [rerun_log.PLANE_COLOURS['plane_I'],
                            rerun_log.PLANE_COLOURS['plane_II'],
                            rerun_log.LEVEL_COLOURS['ERROR']],
    'speed ω': [(80, 200, 255), (255, 200, 60)],
    'drive torque': [(200, 120, 255)],
    'rotating load': list(rerun_log.SUPPORT_COLOURS[:2]),
    'static weight': list(rerun_log.SUPPORT_COLOURS[:2]),
}


def test_every_plot_shows_its_data_on_a_fitted_axis(pictures):
    plots = by_class(pictures, 'TimeSeries')
    assert len(plots) == len(SERIES)
    for word, colours in SERIES.items():
        (name,) = [n for n in plots if word in n]
        image = plots[name][2]
        height, width = image.shape[:2]
        for colour in colours:
            assert colour_pixels(image, colour).sum() >= 40, (name, colour)
        data = saturated(image)
        columns = np.nonzero(data.any(axis=0))[0]
        rows = np.nonzero(data.any(axis=1))[0]
        # Across the run's time axis (the legend alone covers under a fifth of it) ...
        assert len(columns) >= 0.6 * width, (name, len(columns), width)
        # ... and over the height: the axis fits the data, not -1..1.
        assert rows.max() - rows.min() >= 0.4 * height, (name, rows.min(), rows.max())


def test_the_verdict_lanes_go_from_green_to_red(pictures):
    (image,) = [view[2] for view in by_class(pictures, 'StateTimeline').values()]
    r, g, b = (image[:, :, i].astype(int) for i in range(3))
    green = (g > r + 50) & (g > b + 40)       # the lanes are drawn a shade darker
    red = (r > g + 80) & (r > b + 80)
    assert green.sum() > 1000 and red.sum() > 1000, (green.sum(), red.sum())
    # OK before the swap (left), ERROR after it (right).
    assert np.nonzero(green.any(axis=0))[0].mean() < np.nonzero(red.any(axis=0))[0].mean()


def test_the_polar_views_draw_limit_unbalance_and_correction(pictures):
    polar = by_class(pictures, '2D')
    assert len(polar) == 2
    for name, (_, _, image) in polar.items():
        key = 'plane_I' if name.startswith('plane I ') else 'plane_II'
        for colour in (rerun_log.LEVEL_COLOURS['ERROR'], rerun_log.PLANE_COLOURS[key],
                       rerun_log.CORRECTION_COLOUR):
            assert colour_pixels(image, colour).sum() >= 100, (name, colour)


def test_the_3d_view_highlights_the_swapped_tube_and_draws_the_loads(pictures):
    (image,) = [view[2] for view in by_class(pictures, '3D').values()]
    assert colour_pixels(image, rerun_log.CHANGED_COLOUR).sum() >= 300
    assert colour_pixels(image, rerun_log.LOAD_COLOUR).sum() >= 50
    assert colour_pixels(image, rerun_log.CORRECTION_COLOUR).sum() >= 200
