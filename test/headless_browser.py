"""
A local page in headless Chromium at any width, through the DevTools protocol on a pipe.

Chromium's ``--window-size`` stops at 500 pixels; a phone is narrower (390 CSS pixels).
Here the browser is driven over ``--remote-debugging-pipe`` (JSON messages ended by a NUL
on its file descriptors 3 and 4: no network port, no extra package): the page is loaded
with the device metrics of the width asked for (Emulation.setDeviceMetricsOverride, a
mobile viewport), measured with JavaScript (Runtime.evaluate) and photographed
(Page.captureScreenshot).
"""

import base64
import json
import os
from pathlib import Path
import shutil
import subprocess
import tempfile


def chromium():
    """Return the Chromium executable, or None."""
    return shutil.which('chromium') or shutil.which('chromium-browser')


class Browser:
    """Headless Chromium driven over a pipe; a context manager that stops it."""

    def __init__(self, timeout=60.0):
        """Start the browser (raises RuntimeError without Chromium)."""
        browser = chromium()
        if browser is None:
            raise RuntimeError('no chromium on this machine')
        self._profile = tempfile.mkdtemp(prefix='cvc_balance_browser_')
        to_browser, self._send = os.pipe()
        self._receive, from_browser = os.pipe()

        def descriptors():      # in the child: its fds 3 (commands) and 4 (answers)
            # Copies first: a pipe's own fd may be 3 or 4, and dup2 onto itself would
            # leave it closed at exec.
            commands, answers = os.dup(to_browser), os.dup(from_browser)
            os.dup2(commands, 3)
            os.dup2(answers, 4)

        self.process = subprocess.Popen(
            [browser, '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic',
             '--no-first-run', '--disable-background-networking', '--disable-component-update',
             '--disable-sync', '--hide-scrollbars', '--remote-debugging-pipe',
             f'--user-data-dir={self._profile}', 'about:blank'],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, close_fds=False,
            preexec_fn=descriptors, start_new_session=True)
        os.close(to_browser)
        os.close(from_browser)
        self._buffer, self._next, self.events = b'', 0, []
        self.timeout = timeout
        target = self.call('Target.createTarget', url='about:blank')['targetId']
        self.session = self.call('Target.attachToTarget', targetId=target,
                                 flatten=True)['sessionId']
        self.call('Page.enable', session=True)

    def __enter__(self):
        """Return the browser."""
        return self

    def __exit__(self, *exc):
        """Stop the browser and remove its profile."""
        self.close()

    def close(self):
        """Stop the browser (its process group) and remove its profile."""
        for fd in (self._send, self._receive):
            try:
                os.close(fd)
            except OSError:
                pass
        try:
            os.killpg(self.process.pid, 15)
        except ProcessLookupError:
            pass
        try:
            self.process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(self.process.pid, 9)
            self.process.wait()
        shutil.rmtree(self._profile, ignore_errors=True)

    def _message(self):
        import select
        while b'\0' not in self._buffer:
            ready, _, _ = select.select([self._receive], [], [], self.timeout)
            if not ready:
                raise RuntimeError(f'chromium did not answer within {self.timeout:g} s')
            piece = os.read(self._receive, 1 << 20)
            if not piece:
                raise RuntimeError('chromium closed its pipe')
            self._buffer += piece
        text, self._buffer = self._buffer.split(b'\0', 1)
        return json.loads(text)

    def call(self, method, session=False, **params):
        """Send one command; return its result (events that arrive meanwhile are kept)."""
        self._next += 1
        message = {'id': self._next, 'method': method, 'params': params}
        if session:
            message['sessionId'] = self.session
        os.write(self._send, json.dumps(message).encode() + b'\0')
        while True:
            answer = self._message()
            if answer.get('id') == self._next:
                if 'error' in answer:
                    raise RuntimeError(f'{method}: {answer["error"]}')
                return answer.get('result', {})
            self.events.append(answer)

    def wait_for(self, method):
        """Wait for an event of ``method``; return its parameters."""
        for k, event in enumerate(self.events):
            if event.get('method') == method:
                return self.events.pop(k).get('params', {})
        while True:
            event = self._message()
            if event.get('method') == method:
                return event.get('params', {})

    def open(self, path, width, height=900, mobile=False):
        """Load a local page at ``width`` x ``height`` CSS pixels (a phone's if ``mobile``)."""
        self.events = []
        self.call('Emulation.setDeviceMetricsOverride', session=True, width=width,
                  height=height, deviceScaleFactor=1, mobile=mobile)
        self.call('Page.navigate', session=True, url=Path(path).resolve().as_uri())
        self.wait_for('Page.loadEventFired')

    def evaluate(self, expression):
        """Return the value of a JavaScript expression in the page (JSON-able)."""
        result = self.call('Runtime.evaluate', session=True, expression=expression,
                           returnByValue=True, awaitPromise=True)
        if 'exceptionDetails' in result:
            raise RuntimeError(f'{expression[:60]}...: {result["exceptionDetails"]}')
        return result['result'].get('value')

    def screenshot(self, path, full_page=True):
        """Write a PNG of the page (all of it, or the viewport) to ``path``."""
        params = {'format': 'png', 'captureBeyondViewport': full_page}
        if full_page:
            size = self.evaluate('[document.documentElement.scrollWidth, '
                                 'document.documentElement.scrollHeight]')
            params['clip'] = {'x': 0, 'y': 0, 'width': size[0], 'height': size[1], 'scale': 1}
        data = self.call('Page.captureScreenshot', session=True, **params)['data']
        Path(path).write_bytes(base64.b64decode(data))
