"""Read a layout from a YAML or JSON file or text (the layout topic's payload)."""

import json

import yaml

from cvc_balance.physics.layout import LayoutError, parse_layout


def layout_from_text(text, source='layout'):
    """
    Parse YAML or JSON text into a validated Layout.

    JSON (which YAML mostly contains) is tried first so that JSON's NaN and
    Infinity are read as numbers and then rejected by the validation.
    Raises :class:`LayoutError` with one line naming the problem.
    """
    try:
        data = json.loads(text)
    except ValueError:
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as error:
            mark = getattr(error, 'problem_mark', None)
            where = f' line {mark.line + 1}' if mark is not None else ''
            problem = getattr(error, 'problem', None) or str(error).splitlines()[0]
            raise LayoutError(f'{source}:{where}: not valid YAML or JSON: {problem}') from None
    return parse_layout(data)


def load_layout(path):
    """Read and validate the layout file at ``path``."""
    try:
        with open(path, encoding='utf-8') as stream:
            text = stream.read()
    except OSError as error:
        raise LayoutError(f'{path}: cannot read layout file: {error.strerror}') from None
    except UnicodeDecodeError:
        raise LayoutError(f'{path}: layout file is not UTF-8 text') from None
    return layout_from_text(text, source=str(path))
