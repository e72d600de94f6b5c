"""
The fleet's charts as pictures: drawn from fixed inputs and compared pixel by pixel.

The way matplotlib's own image tests work: the charts draw with Agg, matplotlib is pinned
(requirements.txt) with its DejaVu fonts bundled, so the same inputs give the same pixels
(checked: two processes wrote identical pictures). The reference pictures under
``test/data/charts/`` were drawn once by this module and looked at (each test says what a
person sees in its picture); they fix what no assertion on the figure's objects reads:
figure size and resolution, font sizes, line widths, marker and cap sizes, transparency,
alignment and offsets of the texts, the shared time axis. A change to any of them is a
changed picture: look at the new one (the failure names both files) and, if it is meant,
draw the references again::

    ./dev.sh run python test/test_chart_pictures.py --write

The inputs are series made here (no bags): a machine of two planes over two layout
epochs, one plane drifting toward its share (LEAVES GRADE), the other flat (NO
SIGNIFICANT DRIFT); a machine without a plane; a fleet of four (out of grade, leaving,
leaving with no latest date, stable). Drawn under matplotlib's default style, whatever
other tests set.
"""

from datetime import datetime, timezone
from pathlib import Path
import sys

from matplotlib import style
import numpy as np
from PIL import Image

from cvc_balance.fleet.charts import fleet_chart, machine_chart
from cvc_balance.fleet.trends import fit_machine

REFERENCE = Path(__file__).resolve().parent / 'data' / 'charts'
DAY_NS = 86_400 * 10**9
START_NS = 1_760_000_000 * 10**9                     # 2025-10-09 08:53:20 UTC
DAYS = np.array([0.0, 9.0, 20.0, 31.0, 40.0, 52.0, 60.0, 71.0, 83.0, 90.0, 101.0, 112.0])
NOISE = np.array([6.0, -9.0, 4.0, 8.0, -5.0, 2.0, -7.0, 9.0, -3.0, 5.0, -6.0, 1.0])
AFTER = DAYS >= 50.0                                 # the layout change at day 52
MEASURED = np.array([True, False] * 6)


def series(amount_i, amount_ii=None, share=None):
    """Return a machine's runs: plane I (every other run measured), plane II (all)."""
    n = len(DAYS)
    digests = np.where(AFTER, 'b', 'a').astype(object)
    share = np.where(AFTER, 1300.0, 1200.0) if share is None else share
    missing = np.full(n, np.nan)
    return {'t': (START_NS + DAYS * DAY_NS).astype(np.int64), 'layout_digest': digests,
            'layout_name': np.array([f'gantry {d}' for d in digests], dtype=object),
            'grade': np.full(n, 6.3), 'amount_I': np.asarray(amount_i, float),
            'ci95_I': np.where(MEASURED, 20.0 + DAYS / 10.0, np.nan),
            'permissible_I': share, 'identified_I': MEASURED,
            'amount_II': missing if amount_ii is None else np.asarray(amount_ii, float),
            'ci95_II': np.full(n, 15.0), 'permissible_II': share,
            'identified_II': np.ones(n, bool)}


LEAVING = 300.0 + 4.0 * DAYS + 120.0 * AFTER + NOISE
FLAT = 500.0 - NOISE


def two_planes():
    """Plane I drifting 4 g mm/day (a step of 120 g mm at the change), plane II flat."""
    return fit_machine('site/m 1', series(LEAVING, FLAT))


def fleet():
    """Out of grade, leaving, leaving with no latest date, stable: in urgency order."""
    out = fit_machine('out', series(LEAVING + 1000.0))
    leaving = fit_machine('leaving', series(LEAVING))
    unsure = fit_machine('unsure', series(LEAVING))
    unsure.planes[0].leaves_latest = None
    calm = fit_machine('calm', series(FLAT, share=np.full(len(DAYS), 1200.0)))
    return [out, leaving, unsure, calm]


def draw(name, folder):
    """Draw the picture ``name`` into ``folder`` (matplotlib's default style); its path."""
    path = Path(folder) / name
    with style.context('default'):
        if name == 'machine.png':
            machine_chart(two_planes(), path)
        elif name == 'no_plane.png':
            machine_chart(fit_machine('none', series(np.full(len(DAYS), np.nan))), path)
        else:
            fleet_chart(fleet(), path)
    return path


def pixels(path):
    """Return a PNG's decoded pixels, RGBA, (rows, columns, 4) uint8."""
    with Image.open(path) as image:
        return np.asarray(image.convert('RGBA'))


def same_picture(name, tmp_path, size):
    """Draw ``name``, check its size in pixels (by hand) and every pixel against its reference."""
    drawn = pixels(draw(name, tmp_path))
    assert drawn.shape == (size[1], size[0], 4), \
        f'{tmp_path / name}: {drawn.shape[1]} x {drawn.shape[0]} pixels, not {size}'
    reference = pixels(REFERENCE / name)
    assert drawn.shape == reference.shape, \
        f'{tmp_path / name} is {drawn.shape[1]} x {drawn.shape[0]} pixels, ' \
        f'{REFERENCE / name} {reference.shape[1]} x {reference.shape[0]}'
    differ = np.any(drawn != reference, axis=2)
    assert not differ.any(), (
        f'{tmp_path / name} differs from {REFERENCE / name} in {int(differ.sum())} pixels '
        f'(rows {np.flatnonzero(differ.any(axis=1))[[0, -1]].tolist()}, by up to '
        f'{int(np.abs(drawn.astype(int) - reference).max())} of 255): look at both; if '
        'the change is meant, run ./dev.sh run python test/test_chart_pictures.py --write')


def test_a_machines_chart_of_two_planes_is_its_reference_picture(tmp_path):
    """
    Draw the two-plane machine: 990 x 704 pixels (9 x (2.9 * 2 + 0.6) inches at 110 dpi).

    What a person sees in test/data/charts/machine.png: the title 'site/m 1: LEAVES GRADE
    2026-05-18   (layout gantry b, G 6.3, 12 runs)'; two panels sharing one concise date
    axis (Oct to Jun) at the bottom only. The top one, 'plane I: LEAVES GRADE 2026-05-18':
    blue dots with small capped 95 % bars and hollow blue circles between them, rising
    from 300 to about 870 g mm; a thin black fitted line over each epoch, a step up at the
    grey dashed layout change (the end of November), 'layout change: +121 +- 18 g mm' in small
    grey type at its top right; a red step at 1,200 then 1,300 g mm held to the chart's
    end; from the last run a black dashed projection in a light grey band up to the share
    (late May); a pale red shaded interval (mid to late May) and a red dotted line on the
    date; a legend of four entries below the middle. The bottom one, 'plane II: NO
    SIGNIFICANT DRIFT': blue dots with bars along 500 g mm, two flat black lines, the red
    step to the same end, the grey change line and 'layout change: -1 +- 18 g mm', a
    legend at the lower left (the share, 'drift +0 +- 0 g mm/day' as a black line, the
    identified runs); light grid lines in both; y axes in g mm with thousands separators.
    """
    same_picture('machine.png', tmp_path, (990, 704))


def test_a_machine_without_a_plane_is_its_reference_picture(tmp_path):
    """
    Draw the machine without any plane: 990 x 385 pixels (9 x 3.5 inches at 110 dpi).

    What a person sees in test/data/charts/no_plane.png: the title 'none: TOO FEW RUNS
    (layout gantry b, G 6.3, 12 runs)' and, centred in an empty white panel without axes,
    'no correction plane to chart: its runs gave no plane unbalance'.
    """
    same_picture('no_plane.png', tmp_path, (990, 385))


def test_the_fleet_chart_is_its_reference_picture(tmp_path):
    """
    Draw the fleet of four: 880 x 277 pixels (8 x (0.28 * 4 + 1.4) inches at 110 dpi).

    What a person sees in test/data/charts/fleet.png: 'machines by urgency' at the top
    left; four rows labelled out, leaving, unsure, calm in small type, from the top; 'out'
    a red note at zero ('out of grade now (plane I: 1.44 of its share)'); 'leaving' a blue
    bar to about 109 days, a thin black interval line from about 100 to 120 days and
    '2026-05-18 (plane I)' at its end; 'unsure' the same bar, its line to about 218 days
    (twice the days), '2026-05-18 (plane I; may never leave)'; 'calm' a grey 'NO
    SIGNIFICANT DRIFT' at zero, clear of the axis' bottom edge; light vertical grid lines;
    the axis 'days from the last run to leaving the grade (95 % interval)'.
    """
    same_picture('fleet.png', tmp_path, (880, 277))


NAMES = ('machine.png', 'no_plane.png', 'fleet.png')

if __name__ == '__main__':
    # python test/test_chart_pictures.py --write [FOLDER]: draw the references (or into
    # FOLDER, e.g. to check that two processes draw the same pixels).
    if sys.argv[1:2] != ['--write']:
        raise SystemExit('usage: python test/test_chart_pictures.py --write [FOLDER]')
    folder = Path(sys.argv[2]) if len(sys.argv) > 2 else REFERENCE
    folder.mkdir(parents=True, exist_ok=True)
    for picture in NAMES:
        print(draw(picture, folder))
    print(f'drawn {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC: look at each before '
          'committing')
