"""
The field report as people read it: its tables, its figures' text, and on a phone.

The report is the one docs/field_report.png shows, made by the same commands
(docs/pictures.py: the bundled baseline, its trial runs' coefficients, a simulated check
run). Read as HTML: no table has an empty header row, the coefficients table lists the
calibrated sensors and nothing else, each with the value worked out here from the record's
re and im. In Chromium (headless, driven over its DevTools pipe: test/headless_browser.py),
at a desktop's 1100 CSS pixels and a phone's 390: the page is laid out for the width (no
sideways scrolling of the page, every element inside it; a table wider than the phone
scrolls in its own box), and every text in the figures (legends, tick labels, labels) is
11 CSS pixels or more on the desktop and 9 or more on the phone, as displayed.
"""

from html.parser import HTMLParser
import json
import math
from pathlib import Path
import subprocess
import sys

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'docs'))
import pictures  # noqa: E402  (docs/pictures.py: the commands of the shipped picture)

from headless_browser import Browser, chromium  # noqa: E402


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    """Make the report of docs/field_report.png by its steps: (folder, summary, record)."""
    work = tmp_path_factory.mktemp('report')
    (work / 'bags').symlink_to(ROOT / 'bags', target_is_directory=True)
    steps = [s for s in pictures.BY_NAME['field_report'].steps if s[0] == 'cvc-balance']
    for step in steps:
        words = list(step[1:]) + (['--json'] if step[1] == 'report' else [])
        done = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', *words], cwd=work,
                              capture_output=True, text=True)
        assert done.returncode == 0, (step, done.stderr)
    summary = json.loads(done.stdout)['summary']
    record = yaml.safe_load((work / 'coefficients.yaml').read_text())
    return work / 'report', summary, record


class Tables(HTMLParser):
    """Every table of a page: its rows, each a list of (tag, text) cells; the heading above."""

    def __init__(self):
        """Start with none."""
        super().__init__()
        self.tables, self._cell, self._heading, self.heading = [], None, False, ''

    def handle_starttag(self, tag, attrs):
        """Open tables, rows, cells and headings."""
        if tag == 'table':
            self.tables.append((self.heading, []))
        elif tag == 'tr':
            self.tables[-1][1].append([])
        elif tag in ('td', 'th'):
            self._cell = [tag, '']
        elif tag == 'h2':
            self._heading, self.heading = True, ''

    def handle_endtag(self, tag):
        """Close cells and headings."""
        if tag in ('td', 'th') and self._cell is not None:
            self.tables[-1][1][-1].append(tuple(self._cell))
            self._cell = None
        elif tag == 'h2':
            self._heading = False

    def handle_data(self, data):
        """Keep the text of cells and headings."""
        if self._cell is not None:
            self._cell[1] += data
        if self._heading:
            self.heading += data


def tables(folder):
    parser = Tables()
    parser.feed((folder / 'report.html').read_text(encoding='utf-8'))
    return parser.tables


def test_no_table_has_an_empty_row(report):
    found = tables(report[0])
    assert len(found) >= 8
    for heading, rows in found:
        for row in rows:
            assert any(text.strip() for _, text in row), (heading, rows[:2])
    (run,) = [rows for heading, rows in found if heading == 'Run']
    # The run's identity: each row headed by its name, no header row above them.
    assert [row[0] for row in run][:2] == [('th', 'bag'), ('th', 'recorded (first message, UTC)')]
    assert run[0][1] == ('td', 'bags/field_baseline.mcap')


def test_the_coefficients_table_lists_the_calibrated_sensors_only(report):
    """No 'plane I unbalance 1 @ 0.0': the grade's limits are no sensors."""
    folder, summary, record = report
    (rows,) = [rows for heading, rows in tables(folder)
               if heading == 'Influence coefficients used']
    assert [text for _, text in rows[0]] == ['sensor', 'plane I', 'plane II']
    assert [row[0][1] for row in rows[1:]] == record['sensors'] == [
        'front/force_x', 'front/force_y', 'rear/force_x', 'rear/force_y']
    for row, values in zip(rows[1:], record['coefficients']):
        for (_, text), value in zip(row[1:], values):
            z = complex(value['re'], value['im'])
            phase = math.degrees(math.atan2(z.imag, z.real)) % 360.0
            assert text == f'{abs(z):.4g} @ {round(phase, 1) % 360.0:.1f}', (text, z)
    assert summary['coefficients']['sensors'] == record['sensors']
    assert len(summary['coefficients']['values']) == len(record['sensors'])


MEASURE = '''(() => {
  const width = window.innerWidth, out = [];
  for (const e of document.body.querySelectorAll('*')) {
    if (e.closest('.scroll') && !e.classList.contains('scroll')) continue;
    const box = e.getBoundingClientRect();
    if (box.width && box.right > width + 0.5) out.push(e.tagName + ' ' + box.right);
  }
  return {width: width, page: document.documentElement.scrollWidth, outside: out,
          scrolls: [...document.querySelectorAll('.scroll')].map(
            s => [s.clientWidth, s.scrollWidth]),
          images: [...document.images].map(i => [i.getAttribute('src'), i.clientWidth,
                                                  i.naturalWidth, i.complete]),
          boxes: [...document.querySelectorAll('#verdict > div')].map(b => {
            const r = b.getBoundingClientRect(); return [r.left, r.top, r.bottom]; })};
})()'''


@pytest.fixture(scope='module')
def seen(report):
    """Measure the page in Chromium at a desktop's and a phone's width."""
    if chromium() is None:
        pytest.skip('no chromium on this machine (./dev.sh test installs it, as root on '
                    'Debian)')
    found = {}
    with Browser() as browser:
        for name, width, mobile in (('desktop', 1100, False), ('phone', 390, True)):
            browser.open(report[0] / 'report.html', width, 844, mobile=mobile)
            found[name] = browser.evaluate(MEASURE)
            browser.screenshot(report[0] / f'{name}.png')
    return found


@pytest.mark.parametrize('name', ['desktop', 'phone'])
def test_the_page_fits_its_width(seen, name):
    page = seen[name]
    assert page['width'] == {'desktop': 1100, 'phone': 390}[name]   # laid out for it
    assert page['page'] <= page['width'] and not page['outside'], page
    assert page['scrolls'] and all(box <= page['width'] for box, _ in page['scrolls'])
    assert len(page['images']) == 4 and all(done for *_, done in page['images'])
    for src, shown, natural, _ in page['images']:
        assert 0 < shown <= page['width'], (src, shown)
    boxes = page['boxes']
    assert len(boxes) == 3
    if name == 'phone':    # one figure across, the verdict boxes one above the other
        assert all(shown >= 0.85 * page['width'] for _, shown, *_ in page['images'])
        assert all(below[1] >= above[2] for above, below in zip(boxes, boxes[1:])), boxes
    else:                  # side by side
        assert len({round(top) for _, top, _ in boxes}) == 1, boxes


def figure_texts(figure):
    """Return the sizes (px in the PNG) and words of every text drawn in a figure."""
    from matplotlib.text import Text
    figure.canvas.draw()
    return [(t.get_fontsize() * figure.dpi / 72.0, t.get_text())
            for t in figure.findobj(Text) if t.get_visible() and t.get_text().strip()
            and t.get_window_extent().width > 0]


def test_figure_text_is_big_enough_where_it_is_shown(report, seen, tmp_path):
    """Every legend, tick label and label: 11 CSS pixels on a desktop, 9 on a phone."""
    from cvc_balance.report import figures
    _, summary, _ = report
    drawn = {'plane_I.png': figures.plane_figure(summary, 0, tmp_path / 'a.png'),
             'plane_II.png': figures.plane_figure(summary, 1, tmp_path / 'b.png'),
             'grade.png': figures.grade_figure(summary, tmp_path / 'c.png'),
             'readings.png': figures.readings_figure(summary, tmp_path / 'd.png')}
    for name, least in (('desktop', 11.0), ('phone', 9.0)):
        for src, shown, natural, _ in seen[name]['images']:
            scale = shown / natural
            texts = figure_texts(drawn[src])
            assert len(texts) >= 8, (src, texts)
            size, words = min(texts)
            assert size * scale >= least, (name, src, words, size * scale)
