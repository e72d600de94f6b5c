"""
Pictures of a run in rerun's own viewer, rendered headless, at a stated moment.

:class:`HeadlessViewer` starts ``rerun --headless`` (bound to 127.0.0.1 on a free port,
with a private configuration where ``rerun analytics disable`` was run), opens an
``.rrd``, puts the time cursor where it is told (paused) through the viewer's
control API (``rerun.experimental.ViewerClient``), and takes screenshots once the
picture has settled: two consecutive frames alike, so that loading, plot axes and the
start-up notice are done. Nothing depends on timing luck. It needs a Vulkan adapter
(a GPU or Mesa's lavapipe: Debian's ``mesa-vulkan-drivers libvulkan1``).
"""

import io
import os
import shutil
import sys
import signal
import socket
import subprocess
import tempfile
import time

import numpy as np
from PIL import Image
from rerun.experimental import ViewerClient

from cvc_balance.view.rerun_log import TIMELINE

SIZE = (1600, 900)
"""Logical pixels of the viewer's window."""


class ViewerError(RuntimeError):
    """The headless viewer could not start or did not answer; ``str()`` says why."""


class HeadlessViewer:
    """A headless rerun viewer of one .rrd; a context manager that stops it on exit."""

    def __init__(self, rrd, size=SIZE, start_timeout=60.0):
        """Start the viewer and open ``rrd``; raises ViewerError when it cannot."""
        self._work = tempfile.mkdtemp(prefix='cvc_balance_viewer_')
        env = dict(os.environ, XDG_CONFIG_HOME=os.path.join(self._work, 'config'),
                   RERUN_ANALYTICS='false')
        # The viewer comes with rerun-sdk: next to this Python (a venv not on PATH) or on PATH.
        beside = os.path.join(os.path.dirname(sys.executable), 'rerun')
        rerun = beside if os.access(beside, os.X_OK) else shutil.which('rerun')
        if rerun is None:
            raise ViewerError('the rerun viewer (rerun-sdk) is not installed')
        subprocess.run([rerun, 'analytics', 'disable'], env=env, capture_output=True,
                       timeout=60)
        port = _free_port()
        self.log_path = os.path.join(self._work, 'viewer.log')
        self._log = open(self.log_path, 'w')
        # Its own process group: the `rerun` script runs the viewer binary as a child,
        # and both must go when this viewer is closed.
        self.process = subprocess.Popen(
            [rerun, '--headless', '--bind', '127.0.0.1', '--port', str(port),
             '--window-size', f'{size[0]}x{size[1]}', '--hide-welcome-screen'],
            env=env, stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            self.client = self._connect(f'rerun+http://127.0.0.1:{port}/proxy', start_timeout)
            self.client.open(str(os.path.abspath(rrd)))
            self._wait_loaded(start_timeout)
        except BaseException:
            self.close()
            raise

    def __enter__(self):
        """Return the viewer."""
        return self

    def __exit__(self, *exc):
        """Stop the viewer."""
        self.close()

    def close(self):
        """Stop the viewer (its process group, which it alone is in); remove its scratch."""
        group = self.process.pid
        for sig, wait in ((signal.SIGTERM, 10), (signal.SIGKILL, 10)):
            try:
                os.killpg(group, sig)
            except ProcessLookupError:      # the group has gone
                break
            deadline = time.monotonic() + wait
            while time.monotonic() < deadline and _group_alive(group):
                self.process.poll()          # reap the direct child
                time.sleep(0.05)
            if not _group_alive(group):
                break
        self.process.wait()
        self._log.close()
        shutil.rmtree(self._work, ignore_errors=True)

    def log(self):
        """Return what the viewer printed (for error messages)."""
        with open(self.log_path, errors='replace') as stream:
            return stream.read()

    def _connect(self, url, timeout):
        deadline = time.monotonic() + timeout
        while True:
            if self.process.poll() is not None:
                raise ViewerError(f'the headless rerun viewer exited with code '
                                  f'{self.process.returncode}: {_last_line(self.log())}')
            try:
                client = ViewerClient.connect(url)
                client.get_state()
                return client
            except Exception as error:   # not listening yet
                if time.monotonic() > deadline:
                    raise ViewerError(f'the headless rerun viewer did not answer within '
                                      f'{timeout:g} s: {error}') from None
                time.sleep(0.1)

    def _wait_loaded(self, timeout):
        deadline = time.monotonic() + timeout
        while True:
            state = self.client.get_state()
            if not state.loading and state.recordings and state.recordings[0].timelines:
                return state
            if time.monotonic() > deadline:
                raise ViewerError(f'the viewer did not finish loading within {timeout:g} s')
            time.sleep(0.1)

    def timeline(self):
        """(first, last) time of the run's timeline, ns since the run's first sample."""
        for recording in self.client.get_state().recordings:
            for line in recording.timelines:
                if line.name == TIMELINE:
                    return line.start, line.end
        raise ViewerError(f'the recording has no {TIMELINE!r} timeline')

    def at(self, seconds=None):
        """
        Put the time cursor ``seconds`` after the run's first sample, paused.

        None: at the last sample. Returns the cursor's time, ns since the first sample
        (the timeline's 0: the load cells' readings may start before it).
        """
        _, end = self.timeline()
        when = end if seconds is None else round(seconds * 1e9)
        self.client.set_time(TIMELINE, duration=np.timedelta64(when, 'ns'), play_state='paused')
        return when

    def views(self):
        """Return the viewer's views: objects with view_id, view_class, name, reports."""
        return self.client.get_state().views

    def screenshot(self, view_id=None, settle=4.0, frames=4, timeout=90.0):
        """
        Take a settled picture of the viewer (or one view): an RGB array (h, w, 3).

        Frames are taken until the picture has not changed (every pixel within 2 of
        255) for ``settle`` seconds and ``frames`` frames: loading, axis fitting and the
        viewer's start-up notice (which fades with frames, not with time) are over. Once
        the whole picture has settled, a view's own needs fewer (each frame renders the
        whole viewer in software: ~0.3 s of CPU here).
        """
        previous, stable_since, alike = None, None, 0
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            png = self.client.take_screenshot(view_id)
            image = np.asarray(Image.open(io.BytesIO(png)).convert('RGB'))
            now = time.monotonic()
            if previous is not None and previous.shape == image.shape and \
                    np.abs(previous.astype(int) - image.astype(int)).max() <= 2:
                alike += 1
                if alike >= frames - 1 and now - stable_since >= settle:
                    return image
            else:
                stable_since, alike = now, 0
            previous = image
            time.sleep(0.2)
        raise ViewerError(f'the picture did not settle within {timeout:g} s')


def save_png(image, path):
    """Write an RGB array as a PNG file."""
    Image.fromarray(image).save(path, optimize=True)


def render(rrd, png, seconds=None, size=SIZE):
    """
    Write a settled screenshot of ``rrd`` at ``seconds`` after its first sample to ``png``.

    Returns the cursor's time on the timeline, ns.
    """
    with HeadlessViewer(rrd, size) as viewer:
        when = viewer.at(seconds)
        save_png(viewer.screenshot(), png)
    return when


def _group_alive(group):
    """Tell whether any process of the process group ``group`` is still running."""
    try:
        os.killpg(group, 0)
    except ProcessLookupError:
        return False
    return True


def _free_port():
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def _last_line(text):
    lines = [line for line in text.splitlines() if line.strip()]
    return lines[-1] if lines else '(no output)'
