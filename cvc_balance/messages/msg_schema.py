"""
ros2msg schema texts for bags, from the installed .msg files, as rosbag2 writes them.

The main type's .msg text, then each type it uses (depth first, once) after a
line of 80 '=' and ``MSG: pkg/Type``. Files are found through the ament index
or, for PyPI wheels, next to the message package's Python module.
"""

from functools import lru_cache
import importlib
from pathlib import Path

PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16',
              'uint16', 'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'}
SEPARATOR = '=' * 80


def _msg_file(package, name):
    candidates = []
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory(package)))
    except (ImportError, LookupError, OSError, ValueError):
        pass
    module = importlib.import_module(package)
    # <prefix>/lib/pythonX.Y/site-packages/<package>/__init__.py -> <prefix>/share/<package>
    candidates.append(Path(module.__file__).resolve().parents[4] / 'share' / package)
    for share in candidates:
        path = share / 'msg' / f'{name}.msg'
        if path.is_file():
            return path
    raise LookupError(f'no .msg file for {package}/msg/{name} (looked in '
                      f'{", ".join(map(str, candidates))})')


def _field_types(text, package):
    """Compound types used by a .msg text, as 'pkg/Type', in order of appearance."""
    used = []
    for line in text.splitlines():
        tokens = line.split('#', 1)[0].split()
        if len(tokens) < 2 or '=' in tokens[1] or (len(tokens) > 2 and tokens[2][0] == '='):
            continue  # blank, comment or constant
        kind = tokens[0].split('[')[0].split('<=')[0]
        if kind in PRIMITIVES:
            continue
        if kind == 'Header':
            kind = 'std_msgs/Header'
        elif '/' not in kind:
            kind = f'{package}/{kind}'
        used.append(kind)
    return used


@lru_cache(maxsize=None)
def schema_text(msg_type):
    """Return the ros2msg schema of ``msg_type`` ('pkg/msg/Type'), dependencies appended."""
    package, _, name = msg_type.split('/')
    parts, seen = [_msg_file(package, name).read_text()], set()

    def visit(text, owner):
        for dependency in _field_types(text, owner):
            if dependency in seen:
                continue
            seen.add(dependency)
            dep_package, dep_name = dependency.split('/')
            dep_text = _msg_file(dep_package, dep_name).read_text()
            parts.append(f'{SEPARATOR}\nMSG: {dependency}\n{dep_text}')
            visit(dep_text, dep_package)

    visit(parts[0], package)
    return '\n'.join(p.rstrip('\n') for p in parts) + '\n'


@lru_cache(maxsize=None)
def type_hash(msg_type):
    """
    Return the type description hash (RIHS01) of ``msg_type`` ('pkg/msg/Type'), or ''.

    As the installed package states it (``share/<pkg>/msg/<Type>.json``, made by
    rosidl when the package was built); rosbag2 writes it to metadata.yaml.
    """
    import json
    package, _, name = msg_type.split('/')
    try:
        description = json.loads(_msg_file(package, name).with_suffix('.json').read_text())
    except (LookupError, OSError, ValueError):
        return ''
    return next((entry['hash_string'] for entry in description.get('type_hashes', ())
                 if entry.get('type_name') == msg_type), '')
