"""
Which machine a bag was recorded on: its ``machine_id``, written into the bag and read back.

Written by ``cvc-balance simulate --machine-id``, ``cvc-balance record --machine-id`` and
the node's ``machine_id`` parameter through :func:`cvc_balance.bag.rosbag2.open_writer`'s
``custom_data``: an MCAP Metadata record named ``cvc_balance`` (key ``machine_id``) right
after the file's header, the ``custom_data`` of rosbag2's ``rosbag2`` record, and for a
rosbag2 directory ``custom_data: {machine_id: ...}`` in ``metadata.yaml``, where
``ros2 bag record --custom-data machine_id=...`` puts it.

Read back by :func:`bag_custom_data` and :func:`machine_of` from any of: the
``cvc_balance`` record, rosbag2's own ``rosbag2`` record (``serialized_metadata``, the
metadata rosbag2's MCAP storage writes into each file, without metadata.yaml's outer
key), a directory's ``metadata.yaml``. A bag that names no machine gets one from its path (see
:func:`machine_of`). Damaged files give what can be read, never an exception.
"""

from pathlib import Path
import re

from cvc_balance.bag.rosbag2 import METADATA
from cvc_balance.bag.rosbag2_metadata import CUSTOM_DATA_RECORD, RECORD as ROSBAG2_RECORD
from cvc_balance.bag.rosbag2_metadata import SERIALIZED
from cvc_balance.physics.documents import DocumentError, load_document

MACHINE_ID = 'machine_id'
"""The custom-data key of the machine's identity."""
FROM_BAG, FROM_PATH = 'bag', 'path'
"""Where :func:`machine_of` found the identity."""
_ID = re.compile(r'^[A-Za-z0-9][A-Za-z0-9_.:/@+-]{0,127}$')


def check_machine_id(text):
    """
    Return ``text`` if it is a usable machine id, else raise ValueError saying why.

    1-128 characters: letters, digits and ``_ . : / @ + -``, starting with a letter or
    digit (a serial number, an asset tag, a site/machine path), so that it is one token in
    tables, file names of charts and command lines.
    """
    if not isinstance(text, str) or not _ID.match(text):
        raise ValueError(f'machine id {text!r}: give 1-128 letters, digits or _ . : / @ + - '
                         '(starting with a letter or digit)')
    return text


def custom_data(machine_id, label=None):
    """
    Return the ``custom_data`` of a bag recorded on ``machine_id`` (None: nothing to write).

    ``label``: the run's :class:`cvc_balance.bag.run_label.RunLabel` (None: unlabelled).
    """
    data = {MACHINE_ID: check_machine_id(machine_id)} if machine_id else {}
    if label is not None:
        data.update(label.custom_data())
    return data or None


def bag_custom_data(path):
    """
    Return the custom data {key: value} a bag file or rosbag2 directory carries ({}: none).

    A directory: its ``metadata.yaml``'s ``custom_data``, else that of its first MCAP
    file. A file: its ``cvc_balance`` Metadata record, else rosbag2's.
    """
    path = Path(path)
    if path.name == METADATA and path.is_file():
        path = path.parent
    if path.is_dir():
        found = _yaml_custom_data(_read_text(path / METADATA))
        if found:
            return found
        files = sorted(p for p in path.iterdir() if p.suffix == '.mcap')
        return mcap_custom_data(files[0]) if files else {}
    return mcap_custom_data(path) if path.is_file() else {}


def mcap_custom_data(path):
    """Return the custom data of one MCAP file's Metadata records ({}: none or unreadable)."""
    records = _metadata_records(path)
    if CUSTOM_DATA_RECORD in records:
        return dict(records[CUSTOM_DATA_RECORD])
    serialized = records.get(ROSBAG2_RECORD, {}).get(SERIALIZED)
    return _yaml_custom_data(serialized) if serialized else {}


def machine_of(path, root=None):
    """
    Return (machine id, where from) of the bag at ``path``: FROM_BAG or FROM_PATH.

    Without an id in the bag: the bag's folder below ``root`` (the folder searched), as
    service teams file runs (``root/site_a/gantry_17/2026-03-01.mcap`` is
    ``site_a/gantry_17``); a bag directly in ``root`` (or with no root) is its own
    name without suffix.
    """
    found = bag_custom_data(path).get(MACHINE_ID)
    if isinstance(found, str) and found.strip():
        return found.strip(), FROM_BAG
    path = Path(path)
    parent = path.parent
    if root is not None:
        try:
            relative = parent.resolve().relative_to(Path(root).resolve())
        except ValueError:
            relative = None
        if relative is not None and relative.parts:
            return relative.as_posix(), FROM_PATH
    return path.stem if path.suffix else path.name, FROM_PATH


def _read_text(path):
    try:
        return path.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError):
        return None


def _yaml_custom_data(text):
    """
    custom_data of rosbag2's metadata text, {} if none.

    A metadata.yaml (``rosbag2_bagfile_information`` and the metadata under it) or the
    ``serialized_metadata`` of a ``rosbag2`` record (the metadata itself).
    """
    if not text:
        return {}
    try:
        document = load_document(text, as_text=True)     # custom_data: strings
    except DocumentError:
        return {}
    info = document.get('rosbag2_bagfile_information', document) \
        if isinstance(document, dict) else None
    data = info.get('custom_data') if isinstance(info, dict) else None
    if not isinstance(data, dict):
        return {}
    return {str(k): str(v) for k, v in data.items() if v is not None}


def _metadata_records(path):
    """
    Return {name: {key: value}} of an MCAP file's Metadata records ({} if unreadable).

    By the summary's metadata index when there is one (the mcap library's seeking
    reader); else the records after the header, up to the first chunk or message
    (where this project's writer puts them: a truncated recording keeps them).
    """
    from mcap.exceptions import McapError
    from mcap.reader import SeekingReader
    from mcap.records import Chunk, DataEnd, Message, Metadata
    from mcap.stream_reader import StreamReader
    found = {}
    try:
        with open(path, 'rb') as stream:
            try:
                reader = SeekingReader(stream)
                if reader.get_summary() is not None:
                    for record in reader.iter_metadata():
                        found.setdefault(record.name, dict(record.metadata))
                    return found
            except (McapError, ValueError, EOFError, KeyError, IndexError, OSError,
                    UnicodeDecodeError, AssertionError):
                pass
            stream.seek(0)
            for record in StreamReader(stream, emit_chunks=True,
                                       record_size_limit=1 << 26).records:
                if isinstance(record, Metadata):
                    found.setdefault(record.name, dict(record.metadata))
                elif isinstance(record, (Chunk, Message, DataEnd)):
                    break
    except Exception:   # a damaged file: the mcap library raises many kinds; use what was read
        pass
    return found
