"""
ros2msg schema texts for bags, from the installed .msg files, as rosbag2 (Jazzy) writes them.

rosbag2_cpp's ``LocalMessageDefinitionSource::get_full_text``: the main type's .msg
file as it is (bytes unchanged, its last newline kept), then for each type it uses,
in the order of a ``std::set`` (byte order of 'pkg/Type') and depth first, each type
once: a newline, a line of 80 '=', ``MSG: pkg/Type`` and that type's file. So
WrenchStamped is followed by Wrench, Vector3, Header, Time (a blank line before each
separator, since the files end in a newline). The types a text uses are found as
rosbag2 finds them (:data:`FIELD_TYPE`, rosbag2's regular expression): the first word
of a line, when it is not one of rosbag2's primitive types, qualified by the package
of the file it is in when it names no package. Files are found through the ament
index or, for PyPI wheels, next to the message package's Python module.
"""

from functools import lru_cache
import importlib
from pathlib import Path
import re

PRIMITIVES = frozenset({'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8',
                        'int16', 'uint16', 'int32', 'uint32', 'int64', 'uint64', 'string'})
"""rosbag2's PRIMITIVE_TYPES (it has no wstring: none of the types written here uses one)."""
SEPARATOR = '=' * 80
FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
"""rosbag2's MSG_FIELD_TYPE_REGEX: a field's type, the first word of a line ("pkg/T[] x")."""


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


def _msg_text(msg_type):
    """Return the .msg file of 'pkg/Type' or 'pkg/msg/Type' as its bytes say (newlines kept)."""
    package, *_, name = msg_type.split('/')
    return _msg_file(package, name).read_bytes().decode('utf-8')


def dependencies(text, package):
    """Return the compound types a .msg text uses, as rosbag2 lists them: sorted 'pkg/Type'."""
    used = set()
    for match in FIELD_TYPE.finditer(text):
        kind = match.group(1)
        if kind in PRIMITIVES:
            continue
        used.add(kind if '/' in kind else f'{package}/{kind}')
    return sorted(used, key=lambda kind: kind.encode())


@lru_cache(maxsize=None)
def schema_text(msg_type):
    """Return the ros2msg schema of ``msg_type`` ('pkg/msg/Type'), as rosbag2 writes it."""
    seen = set()

    def full_text(kind):
        text = _msg_text(kind)
        for dependency in dependencies(text, kind.split('/')[0]):
            if dependency not in seen:
                seen.add(dependency)
                text += f'\n{SEPARATOR}\nMSG: {dependency}\n' + full_text(dependency)
        return text

    return full_text(msg_type)


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
