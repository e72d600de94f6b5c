"""
Every picture the README and the documentation show, made again from the bundled inputs.

    ./dev.sh pictures [NAME ...]     all of them (or the named ones), then the manifest
    ./dev.sh pictures --list         their names, files and commands
    ./dev.sh pictures --check        which shipped pictures are stale, and why

Each picture is made by the project's own commands from files in bags/ and config/ only
(in a scratch folder; the picture replaces the shipped one only when it was made), and
docs/pictures.json records what it was made from: the digests of its inputs (their bytes,
and the digest of every layout in them, the one the pictures print), of the code that
draws it (its Python, comments and docstrings aside) and of the PNG itself.
test/test_pictures.py recomputes them: a picture whose layout, bag or drawing code changed
since it was made fails, naming itself and the command that makes it again. docs/pictures.md
(written here too) lists each picture, what it shows and its command.

The rerun viewer renders headless with Mesa's Vulkan drivers and the report in Chromium
(``./dev.sh pictures`` installs both on Debian as root). Measured pictures (the bench: time
per sample) differ from machine to machine; the others are the same on every run here.
"""

import argparse
import ast
from dataclasses import dataclass
import hashlib
import json
import os
from pathlib import Path
import shlex
import shutil
import subprocess
import sys
import tempfile

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / 'docs' / 'pictures.json'
PAGE = ROOT / 'docs' / 'pictures.md'
COMMAND = './dev.sh pictures'
REPORT_WINDOW = (1100, 1720)
"""CSS pixels of the report's picture: down to its figures, what an engineer reads first."""
VIEWER_AT = 6.5
"""s after the loose-bracket bag's first sample: out of grade by its cells, OK by its layout."""


@dataclass(frozen=True)
class Picture:
    """
    One picture: its file, what it shows, what it is made from and how.

    ``inputs`` and ``code`` are paths from the repository's root; ``steps`` the commands,
    run in a scratch folder where bags/ and config/ are the repository's (argument lists:
    ``{png}`` where the picture goes; a first word ``cvc-balance`` the project's command,
    ``python`` this Python, ``chromium`` a page's screenshot, ``copy`` a file copied).
    """

    name: str
    png: str
    shows: str
    inputs: tuple
    code: tuple
    steps: tuple
    measured: bool = False

    def command(self):
        """Return what a person runs to make this picture again."""
        return f'{COMMAND} {self.name}'


def _sweep(name, layout, component, *rest, shows):
    return Picture(
        name, f'docs/{name}.png', shows, (f'config/{layout}.yaml',),
        ('cvc_balance/design/charts.py',),
        (('cvc-balance', 'sweep', f'config/{layout}.yaml', '--component', component, *rest,
          '-o', '{png}'),))


PICTURES = (
    Picture(
        'viewer', 'docs/viewer.png',
        'the rerun viewer on bags/loose_bracket.mcap, rendered headless, 6.5 s after its first '
        'sample: the load cells find the hidden bracket (ERROR, G 8.4) while the layout alone '
        'would say OK; the gantry, its correction planes, every plot and the events',
        ('bags/loose_bracket.mcap',),
        ('cvc_balance/view/rerun_log.py', 'cvc_balance/view/screenshot.py'),
        (('cvc-balance', 'view', 'bags/loose_bracket.mcap', '-o', 'run.rrd',
          '--screenshot', '{png}', '--at', str(VIEWER_AT)),)),
    Picture(
        'field_report', 'docs/field_report.png',
        'the field-balancing report of the bundled baseline run, with the coefficients of '
        'the bundled trial runs and a simulated check run (bags/field_check.yaml), in '
        'Chromium: the verdict, what to bolt where, the figures',
        ('bags/field_baseline.mcap', 'bags/field_trial_I.mcap', 'bags/field_trial_II.mcap',
         'bags/field_check.yaml', 'config/ct_gantry_field.yaml'),
        ('cvc_balance/report/__init__.py', 'cvc_balance/report/page.py',
         'cvc_balance/report/figures.py'),
        (('cvc-balance', 'simulate', 'bags/field_check.yaml', '-o', 'check.mcap'),
         ('cvc-balance', 'calibrate', 'bags/field_baseline.mcap', 'bags/field_trial_I.mcap',
          'bags/field_trial_II.mcap', '--trial', 'I:0.2@0,0.68', '--trial', 'II:0.2@0,0.68',
          '-o', 'coefficients.yaml'),
         ('cvc-balance', 'report', 'bags/field_baseline.mcap', '--coefficients',
          'coefficients.yaml', '--after', 'check.mcap', '-o', 'report'),
         ('chromium', 'report/report.html', '{png}'))),
    _sweep('design_two_particles_map', 'thesis_two_particles', 'B', '--parameter', 'radius',
           '--range', '0', '2', '--parameter', 'angle', '--range', '0', '360',
           shows='thesis Fig. 4.2: the worse plane and F_res over R2 and phi, two particles'),
    _sweep('design_two_particles_r2', 'thesis_two_particles', 'B', '--parameter', 'radius',
           '--range', '0', '2', '--derivative',
           shows='thesis Figs. 4.2 and 4.3 along R2 at phi = 180 deg: the grade band, the '
           'loads and the derivative of F_res'),
    _sweep('design_two_particles_phi', 'thesis_two_particles', 'B', '--parameter', 'angle',
           '--range', '0', '360', '--derivative',
           shows='thesis Fig. 4.4 along phi at R2 = 1 m'),
    _sweep('design_three_particles_map', 'thesis_three_particles', 'C', '--parameter',
           'radius', '--range', '0', '2', '--parameter', 'angle', '--range', '0', '360',
           shows='thesis Fig. 4.6: three particles over R3 and gamma'),
    _sweep('design_three_particles_r3', 'thesis_three_particles', 'C', '--parameter',
           'radius', '--range', '0', '2', '--derivative',
           shows='thesis Fig. 4.7 along R3 at gamma = 240 deg'),
    _sweep('design_three_particles_gamma', 'thesis_three_particles', 'C', '--parameter',
           'angle', '--range', '0', '360', '--derivative',
           shows='thesis Fig. 4.8 along gamma at R3 = 1 m'),
    _sweep('design_gantry_counterweight', 'ct_gantry', 'counterweight_rear', '--parameter',
           'angle', '--range', '250', '290', '--derivative',
           shows="the demo gantry's rear counterweight angle: how narrow G 6.3 is there"),
    Picture(
        'fleet_machine', 'docs/fleet_machine.png',
        "one machine of a simulated fleet (8 machines, 6 runs each, seed 0): gantry-0001's "
        'slipping counterweight, plane II drifting towards its share of G 6.3',
        ('config/ct_gantry.yaml',),
        ('cvc_balance/fleet/charts.py', 'cvc_balance/fleet/simulate.py'),
        (('cvc-balance', 'simulate-fleet', 'config/ct_gantry.yaml', '-o', 'fleet',
          '--machines', '8', '--runs', '6'),
         ('cvc-balance', 'fleet', 'fleet', '--out', 'fleet.parquet', '--engine', 'local'),
         ('cvc-balance', 'trends', 'fleet.parquet', '--machine', 'gantry-0001', '-o', 'charts'),
         ('copy', 'charts/gantry-0001.png', '{png}'))),
    Picture(
        'identify_accuracy', 'docs/identify_accuracy.png',
        'the unbalance identified from load cells: rms error against the window and the '
        "cells' noise, beside the fit's own standard error (30 seeded runs a point)",
        ('bags/loose_bracket.yaml', 'config/ct_gantry.yaml'),
        ('benchmarks/identify.py',),
        (('python', 'benchmarks/identify.py', '--no-cost', '--png', '{png}'),)),
    Picture(
        'bench', 'docs/bench.png',
        'error against time per sample of every way to compute the loads, per scene '
        '(measured: the times are this machine\'s; also writes docs/bench.csv)',
        (), ('cvc_balance/study/bench.py', 'cvc_balance/study/methods.py'),
        (('cvc-balance', 'bench', '--full', '--csv', 'docs/bench.csv', '--png', '{png}'),),
        measured=True),
)
BY_NAME = {p.name: p for p in PICTURES}


# -- digests ---------------------------------------------------------------------------

def file_digest(path):
    """Return the hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, 'rb') as stream:
        for piece in iter(lambda: stream.read(1 << 20), b''):
            digest.update(piece)
    return digest.hexdigest()


def code_digest(path):
    """
    Return the hex SHA-256 of a Python file's code: its syntax tree without docstrings.

    Comments, docstrings and layout do not change what a picture shows; any change to the
    code does.
    """
    tree = ast.parse(Path(path).read_text(encoding='utf-8'))
    for node in ast.walk(tree):
        body = getattr(node, 'body', None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) and \
                isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
            node.body = body[1:] or [ast.Pass()]
    return hashlib.sha256(ast.dump(tree, include_attributes=False).encode()).hexdigest()


def layout_digests(path):
    """
    Return the digests of the layouts a file holds, as cvc_balance prints them.

    A layout file: its own; a bag: each /layout message's, in order; other files (a
    scenario) hold none of their own.
    """
    path = Path(path)
    if path.suffix == '.mcap':
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
        from cvc_balance.physics.layout_file import layout_from_text
        found = []
        with open(path, 'rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, _, message in reader.iter_decoded_messages(topics=['/layout']):
                found.append(layout_from_text(message.data, source=str(path)).digest())
        return found
    if path.parts[0] == 'config':
        from cvc_balance.physics.layout_file import load_layout
        return [load_layout(ROOT / path).digest()]
    return []


def entry(picture):
    """Return the manifest's entry of a picture as it is now in the working tree."""
    return {
        'png': picture.png, 'command': picture.command(), 'measured': picture.measured,
        'png_sha256': file_digest(ROOT / picture.png) if (ROOT / picture.png).exists()
        else None,
        'inputs': {p: file_digest(ROOT / p) for p in picture.inputs},
        'layouts': {p: digests for p in picture.inputs
                    if (digests := layout_digests(Path(p)))},
        'code': {p: code_digest(ROOT / p) for p in picture.code},
    }


def load_manifest():
    """Return the shipped manifest ({} when there is none)."""
    if not MANIFEST.exists():
        return {}
    return json.loads(MANIFEST.read_text(encoding='utf-8'))


def stale(name, manifest=None):
    """
    Return why the shipped picture ``name`` is stale, one line each ([] when it is not).

    Compared with the manifest: the PNG itself, each input's bytes and layouts, each file
    of the code that draws it, and the lists of them.
    """
    picture = BY_NAME[name]
    manifest = load_manifest() if manifest is None else manifest
    recorded = manifest.get(name)
    if recorded is None:
        return ['not in docs/pictures.json']
    now = entry(picture)
    reasons = []
    if now['png_sha256'] is None:
        reasons.append(f'{picture.png} is missing')
    elif now['png_sha256'] != recorded.get('png_sha256'):
        reasons.append(f'{picture.png} is not the picture the manifest describes')
    for key, what in (('inputs', 'input'), ('code', 'code')):
        old, new = recorded.get(key, {}), now[key]
        for path in sorted(set(old) | set(new)):
            if old.get(path) != new.get(path):
                reasons.append(f'{what} {path} changed' if path in old and path in new else
                               f'{what} {path} {"added" if path in new else "no longer used"}')
    old_layouts, new_layouts = recorded.get('layouts', {}), now['layouts']
    for path in sorted(set(old_layouts) | set(new_layouts)):
        if old_layouts.get(path) != new_layouts.get(path):
            reasons.append(f'the layout digest of {path}: '
                           f'{", ".join(old_layouts.get(path, [])) or "none"} then, '
                           f'{", ".join(new_layouts.get(path, [])) or "none"} now')
    return reasons


# -- making them -------------------------------------------------------------------------

def chromium():
    """Return the Chromium executable, or None."""
    return shutil.which('chromium') or shutil.which('chromium-browser')


def screenshot_html(page, png, window=REPORT_WINDOW):
    """Render a local HTML page in headless Chromium at ``window`` CSS pixels into ``png``."""
    browser = chromium()
    if browser is None:
        raise SystemExit('pictures: Chromium is needed for the report (Debian: apt-get '
                         'install chromium; ./dev.sh pictures installs it as root)')
    with tempfile.TemporaryDirectory(prefix='cvc_balance_chromium_') as profile:
        done = subprocess.run(
            [browser, '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic',
             '--no-first-run', '--disable-background-networking', '--disable-component-update',
             '--disable-sync', '--hide-scrollbars', '--force-device-scale-factor=1',
             f'--user-data-dir={profile}', f'--window-size={window[0]},{window[1]}',
             f'--screenshot={png}', Path(page).resolve().as_uri()],
            capture_output=True, text=True, timeout=180)
    if not Path(png).exists():
        raise SystemExit(f'pictures: Chromium made no picture of {page}: '
                         f'{done.stderr.strip().splitlines()[-1:]}')


def run_steps(picture, work, png):
    """Run a picture's steps in ``work`` (the repository's folders linked in), to ``png``."""
    for folder in ('bags', 'config', 'docs', 'benchmarks'):
        link = work / folder
        if not link.exists():
            link.symlink_to(ROOT / folder, target_is_directory=True)
    for step in picture.steps:
        words = [w.format(png=png) for w in step]
        if words[0] == 'chromium':
            screenshot_html(work / words[1], words[2])
            continue
        if words[0] == 'copy':
            shutil.copyfile(work / words[1], words[2])
            continue
        if words[0] == 'cvc-balance':
            words = [sys.executable, '-m', 'cvc_balance.cli'] + words[1:]
        elif words[0] == 'python':
            words = [sys.executable] + words[1:]
        print('  $ ' + shown(picture, step), flush=True)
        done = subprocess.run(words, cwd=work, env=dict(os.environ, PYTHONPATH=str(ROOT)),
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f'pictures: {picture.name}: {shown(picture, step)} failed '
                             f'(exit {done.returncode}):\n{done.stderr.strip()}')


def make(picture):
    """Make one picture in a scratch folder; replace the shipped one once it is made."""
    with tempfile.TemporaryDirectory(prefix=f'cvc_balance_{picture.name}_') as scratch:
        work = Path(scratch)
        png = work / 'picture.png'
        run_steps(picture, work, png)
        if not png.exists():
            raise SystemExit(f'pictures: {picture.name}: its steps made no picture')
        shutil.move(png, ROOT / picture.png)
    print(f'{picture.png}: made', flush=True)


def page():
    """Return docs/pictures.md: each picture, what it shows, its command and its inputs."""
    lines = ['# Pictures', '',
             'Every picture the README and these pages show, made from the bundled bags and '
             'configurations only by one command, `./dev.sh pictures` (or `./dev.sh pictures '
             'NAME` for one). `docs/pictures.json` records what each was made from (its '
             'inputs, the layout digests in them, the code that draws it); '
             '`test/test_pictures.py` fails when a shipped picture is stale, naming it and '
             'its command. This page is written by `docs/pictures.py`.', '']
    for picture in PICTURES:
        steps = '\n'.join('    ' + shown(picture, step) for step in picture.steps)
        lines += [f'## {picture.name}', '', picture.shows[0].upper() + picture.shows[1:] + '.',
                  '', f'![{picture.name}]({Path(picture.png).name})', '',
                  f'`{picture.command()}` runs:', '', steps, '',
                  'Inputs: ' + (', '.join(f'`{p}`' for p in picture.inputs) or 'none (the '
                                'scenes are made in code, seeded)')
                  + '; drawn by ' + ', '.join(f'`{p}`' for p in picture.code) + '.', '']
    return '\n'.join(lines)


def shown(picture, step):
    """Return a step as a person types it (the picture's own path for ``{png}``)."""
    words = [w.format(png=picture.png) for w in step]
    if words[0] == 'chromium':
        return f'chromium --headless --window-size={REPORT_WINDOW[0]},{REPORT_WINDOW[1]} ' \
            f'--screenshot={words[2]} {words[1]}'
    if words[0] == 'copy':
        return shlex.join(['cp'] + words[1:])
    return shlex.join(words)


def write_manifest(names):
    """Record the named pictures as they are now; keep the others' records as they were."""
    manifest = load_manifest()
    for name in names:
        manifest[name] = entry(BY_NAME[name])
    manifest = {p.name: manifest[p.name] for p in PICTURES if p.name in manifest}
    MANIFEST.write_text(json.dumps(manifest, indent=2) + '\n', encoding='utf-8')
    PAGE.write_text(page(), encoding='utf-8')


def main(argv=None):
    """Make the pictures asked for (default: all), then write the manifest and the page."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('names', nargs='*', metavar='NAME',
                        help='pictures to make (default: all): ' + ', '.join(BY_NAME))
    parser.add_argument('--list', action='store_true', help='list the pictures and stop')
    parser.add_argument('--check', action='store_true',
                        help='only say which shipped pictures are stale (exit 1 if any)')
    parser.add_argument('--record', action='store_true',
                        help='record the named pictures as shipped, without making them: a '
                        'measured one made by its own command (cvc-balance bench)')
    args = parser.parse_args(argv)
    if args.list:
        for picture in PICTURES:
            print(f'{picture.name:30s} {picture.png:40s} {picture.command()}')
        return 0
    if args.check:
        found = {p.name: stale(p.name) for p in PICTURES}
        for name, reasons in found.items():
            print(f'{name}: ' + ('; '.join(reasons) if reasons else 'current'))
        return 1 if any(found.values()) else 0
    unknown = [n for n in args.names if n not in BY_NAME]
    if unknown:
        parser.error(f'no picture {", ".join(unknown)} (pictures: {", ".join(BY_NAME)})')
    names = args.names or [p.name for p in PICTURES]
    if args.record:
        if not args.names:
            parser.error('--record: name the pictures to record')
        write_manifest(names)
        return 0
    for name in names:
        print(f'{BY_NAME[name].png}: {BY_NAME[name].command()}', flush=True)
        make(BY_NAME[name])
        write_manifest([name])
    return 0


if __name__ == '__main__':
    sys.exit(main())
