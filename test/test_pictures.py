"""
The shipped pictures are current: made from today's inputs by today's drawing code.

docs/pictures.json records, for every picture the README and the docs show, what it was
made from (``./dev.sh pictures`` writes it: docs/pictures.py). Here it is recomputed:
the PNG is the one recorded, each input's bytes and the digests of the layouts in it are
the same (a picture printing a layout digest that no longer exists fails here), and so is
the code that draws it (its syntax tree: comments and docstrings may change). A stale
picture fails naming itself and the command that makes it again. Every picture the
README and the docs pages show is in the manifest, and docs/pictures.md is the page
docs/pictures.py writes.
"""

import hashlib
from pathlib import Path
import re
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'docs'))
import pictures  # noqa: E402


@pytest.fixture(scope='module')
def manifest():
    return pictures.load_manifest()


def test_every_picture_is_recorded(manifest):
    assert list(manifest) == [p.name for p in pictures.PICTURES]
    for picture in pictures.PICTURES:
        recorded = manifest[picture.name]
        assert recorded['png'] == picture.png and recorded['command'] == picture.command()


@pytest.mark.parametrize('name', [p.name for p in pictures.PICTURES])
def test_the_picture_is_current(manifest, name):
    reasons = pictures.stale(name, manifest)
    assert not reasons, (f'{pictures.BY_NAME[name].png} is stale: {"; ".join(reasons)}. '
                         f'Make it again: {pictures.BY_NAME[name].command()}')


def shown_pictures():
    """{picture file under docs/: [pages showing it]} of the README and every docs page."""
    pages = [ROOT / 'README.md'] + sorted((ROOT / 'docs').rglob('*.md'))
    shown = {}
    for page in pages:
        if '_build' in page.parts:
            continue
        for target in re.findall(r'!\[[^\]]*\]\(([^)\s]+)', page.read_text(encoding='utf-8')):
            path = (page.parent / target).resolve()
            shown.setdefault(str(path.relative_to(ROOT)), []).append(page.name)
    return shown


def test_every_picture_shown_is_made_by_the_command():
    shown = shown_pictures()
    made = {p.png for p in pictures.PICTURES}
    assert set(shown) <= made, {p: shown[p] for p in set(shown) - made}
    # ... and each made picture is shown (at least on docs/pictures.md).
    assert made <= set(shown), made - set(shown)


def test_the_pictures_page_is_the_one_written():
    assert (ROOT / 'docs' / 'pictures.md').read_text(encoding='utf-8') == pictures.page()


def test_staleness_is_found_and_named(manifest, tmp_path, monkeypatch):
    """A changed layout, bag or drawing code is found, by what changed."""
    picture = pictures.BY_NAME['field_report']
    recorded = {picture.name: dict(manifest[picture.name])}
    # The layout digest the picture prints, as if made from another layout.
    layouts = dict(recorded[picture.name]['layouts'])
    layouts['config/ct_gantry_field.yaml'] = ['a5beacaabeeb']
    recorded[picture.name]['layouts'] = layouts
    (reason,) = pictures.stale(picture.name, recorded)
    digest = pictures.layout_digests(Path('config/ct_gantry_field.yaml'))[0]
    assert reason == (f'the layout digest of config/ct_gantry_field.yaml: a5beacaabeeb then, '
                      f'{digest} now')
    # Its drawing code, changed in what it does (not in a comment): found.
    page = (ROOT / 'cvc_balance' / 'report' / 'page.py').read_text(encoding='utf-8')
    copy = tmp_path / 'page.py'
    copy.write_text(page + '\n# a comment\n', encoding='utf-8')
    shipped = pictures.code_digest(ROOT / 'cvc_balance' / 'report' / 'page.py')
    assert pictures.code_digest(copy) == shipped
    copy.write_text(page.replace('max-width: 62em', 'max-width: 60em'), encoding='utf-8')
    assert pictures.code_digest(copy) != shipped
    # The PNG itself, replaced by hand without the command: found.
    real = pictures.file_digest
    monkeypatch.setattr(pictures, 'file_digest', lambda path: hashlib.sha256(b'x').hexdigest()
                        if str(path).endswith('field_report.png') else real(path))
    assert pictures.stale(picture.name, manifest) == [
        'docs/field_report.png is not the picture the manifest describes']
