"""
rosbag2's bag metadata as ROS 2 Jazzy writes it: metadata.yaml, the MCAP ``rosbag2`` record, QoS.

Jazzy's rosbag2 keeps one ``BagMetadata`` (version 9) and writes it twice, with the
same YAML emitter (yaml-cpp's, default settings: :func:`emit`):

* ``metadata.yaml`` beside the files of a directory: ``rosbag2_bagfile_information:``
  and the metadata under it (``MetadataIo::write_metadata``, no newline at the end);
* in each MCAP file, a Metadata record named ``rosbag2`` with one key,
  ``serialized_metadata``, the same metadata without the outer key
  (``MCAPStorage::update_metadata``): once right after the header, when the file is
  opened (no topics yet, the start at ``nanoseconds::max()``), and once when it is
  closed, the last one being what ``ros2 bag info FILE.mcap`` reads its ROS distro
  (and custom data) from.

The keys come in the order of rosbag2's ``convert<BagMetadata>::encode``; topics in the
order the channels were made (rosbag2's own order is an unordered_map's, so no file can
match it byte for byte there). Offered QoS deviates from Jazzy's bytes on purpose, so
that every reader takes it alike:

* in each MCAP channel's ``offered_qos_profiles`` (:func:`channel_qos`), which Foxglove
  reads too: policies as integers (reliability 2 = best effort), as Foxy to Iron wrote
  them. Foxglove's QoS parser (``@foxglove/rosbag2`` ``parseQosProfiles``) reads
  integers only: Jazzy's strings (``best_effort``) become its defaults, reliable and
  volatile, so a best-effort or latched topic would read as neither. rosbag2 reads
  integers as well as strings (it tells them apart by the history field);
* everywhere (channels, metadata.yaml, the ``rosbag2`` record), an infinite duration as
  Fast DDS's Foxy value {sec: 2147483647, nsec: 4294967295} (:data:`FOXY_INFINITE`),
  not Jazzy's ``RMW_DURATION_INFINITE`` {9223372036, 854775807}: rosbag2 maps the Foxy
  value to ``RMW_DURATION_INFINITE`` and Foxglove's parser takes exactly it as
  infinite, where it would read Jazzy's as a finite 292 years. The same value in
  metadata.yaml as in the channels, since rosbags matches a directory's topics to the
  files' channels by their QoS too (it read no message of a directory whose two
  differed);
* in the YAML metadata, policies as strings, as version 9 writes them.
"""

ROS_DISTRO = 'jazzy'
"""The distribution of the ROS 2 message packages installed (requirements.txt's wheels)."""
VERSION = 9
"""metadata.yaml version written (rosbag2 of ROS 2 Jazzy)."""
RECORD = 'rosbag2'
"""Name of the MCAP Metadata record rosbag2 writes; its key is :data:`SERIALIZED`."""
SERIALIZED = 'serialized_metadata'
CUSTOM_DATA_RECORD = 'cvc_balance'
"""Name of the MCAP Metadata record holding a bag's custom data (the machine's identity)."""
NEVER = (1 << 63) - 1
"""rosbag2's start time of a file before its first message: std::chrono::nanoseconds::max()."""
FOXY_INFINITE = {'sec': 2147483647, 'nsec': 4294967295}
"""Fast DDS's infinite duration in Foxy's bags: infinite to rosbag2 and to Foxglove alike."""

_POLICIES = {      # rmw's enum values and their names in metadata version 9
    'history': {'system_default': 0, 'keep_last': 1, 'keep_all': 2, 'unknown': 3},
    'reliability': {'system_default': 0, 'reliable': 1, 'best_effort': 2, 'unknown': 3,
                    'best_available': 4},
    'durability': {'system_default': 0, 'transient_local': 1, 'volatile': 2, 'unknown': 3,
                   'best_available': 4},
    'liveliness': {'system_default': 0, 'automatic': 1, 'manual_by_topic': 3, 'unknown': 4,
                   'best_available': 5},
}


# -- yaml-cpp's emitter --------------------------------------------------------------

def emit(node):
    """
    Return ``node`` as yaml-cpp's ``YAML::Dump`` writes it (block style, indent 2).

    ``node``: dicts (keys in order), lists, str, int, bool and None. A map's value that is
    a map or a non-empty list goes on the next lines, two spaces in; an empty list is
    ``[]`` there; a list item's first line follows its ``- ``. No newline at the end.
    """
    return '\n'.join(_lines(node, 0))


def _lines(node, indent):
    pad = ' ' * indent
    if isinstance(node, dict):
        out = []
        for key, value in node.items():
            if isinstance(value, (dict, list)) and value:
                out.append(f'{pad}{_scalar(key)}:')
                out += _lines(value, indent + 2)
            elif isinstance(value, list):
                out += [f'{pad}{_scalar(key)}:', f'{pad}  []']
            else:
                out.append(f'{pad}{_scalar(key)}: {_scalar(value)}')
        return out
    if isinstance(node, list):
        out = []
        for item in node:
            inner = _lines(item, indent + 2) if isinstance(item, (dict, list)) and item \
                else [pad + '  ' + _scalar(item)]
            out.append(f'{pad}- {inner[0][indent + 2:]}')
            out += inner[1:]
        return out
    return [pad + _scalar(node)]


def _scalar(value):
    if value is None:
        return '~'
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    text = str(value)
    return text if _plain(text) else _double_quoted(text)


_NOT_FIRST = set(',[]{}#&*!|>\'"%@`')
_NOT_PRINTABLE = {chr(c) for c in range(0x20) if c not in (0x09, 0x0A, 0x0D)} | {'\x7f'}


def _plain(text):
    """Whether yaml-cpp writes ``text`` unquoted (its IsValidPlainScalar, block context)."""
    if text in ('', '~', 'null', 'Null', 'NULL'):
        return False
    first, second = text[0], text[1:2]
    if first in ' \t\r\n' or first in _NOT_FIRST or \
            (first in '-?:' and second in ('', ' ', '\t', '\r', '\n')):
        return False
    if text.endswith(' '):
        return False
    for i, char in enumerate(text):
        after = text[i + 1:i + 2]
        if char == ':' and after in ('', ' ', '\t', '\r', '\n'):
            return False
        if char in ' \t\r\n' and after == '#':
            return False
        if char in '\t\r\n&\ufeff' or char in _NOT_PRINTABLE or \
                '\x80' <= char <= '\x84' or '\x86' <= char <= '\x9f':
            return False
    return True


def _double_quoted(text):
    """``text`` as yaml-cpp double-quotes it (WriteDoubleQuotedString)."""
    escapes = {'"': '\\"', '\\': '\\\\', '\n': '\\n', '\t': '\\t', '\r': '\\r', '\b': '\\b',
               '\f': '\\f'}
    out = []
    for char in text:
        code = ord(char)
        if char in escapes:
            out.append(escapes[char])
        elif code < 0x20 or 0x80 <= code <= 0xA0:
            out.append(f'\\x{code:02x}')
        elif code == 0xFEFF:
            out.append('\\ufeff')
        else:
            out.append(char)
    return '"' + ''.join(out) + '"'


# -- QoS -----------------------------------------------------------------------------

def qos_profile(best_effort=False, latched=False):
    """
    Return a publisher's offered QoS as metadata version 9 writes it (a mapping).

    What Jazzy's recorder stores of a publisher: history and depth unknown to the
    middleware (``unknown``, 0), the reliability and durability offered, no deadline,
    lifespan or lease (infinite: :data:`FOXY_INFINITE`, see the module's description),
    automatic liveliness.
    """
    return {'history': 'unknown', 'depth': 0,
            'reliability': 'best_effort' if best_effort else 'reliable',
            'durability': 'transient_local' if latched else 'volatile',
            'deadline': dict(FOXY_INFINITE), 'lifespan': dict(FOXY_INFINITE),
            'liveliness': 'automatic', 'liveliness_lease_duration': dict(FOXY_INFINITE),
            'avoid_ros_namespace_conventions': False}


def channel_qos(best_effort=False, latched=False):
    """
    Return an MCAP channel's ``offered_qos_profiles``: :func:`qos_profile`, policies as integers.

    The one form both rosbag2 and Foxglove read the same (see the module's description).
    """
    profile = qos_profile(best_effort, latched)
    for policy, values in _POLICIES.items():
        profile[policy] = values[profile[policy]]
    return emit([profile])


def offered(profiles):
    """
    Return (best effort, latched) of offered QoS profiles, in either form rosbag2 reads.

    ``profiles``: a channel's ``offered_qos_profiles`` text or a metadata.yaml list;
    best effort (latched) when any profile offers it. Unreadable: (False, False).
    """
    from cvc_balance.physics.documents import DocumentError, load_document
    if isinstance(profiles, (str, bytes)):
        try:
            profiles = load_document(profiles)
        except DocumentError:
            return False, False
    best_effort = latched = False
    for profile in profiles if isinstance(profiles, list) else ():
        if isinstance(profile, dict):
            best_effort |= profile.get('reliability') in (2, 'best_effort')
            latched |= profile.get('durability') in (1, 'transient_local')
    return best_effort, latched


# -- BagMetadata ---------------------------------------------------------------------

def bag_metadata(files, topics, custom_data=None):
    """
    Return rosbag2's BagMetadata (version 9) as a mapping in its YAML order.

    ``files``: [(file name, first log time ns or None, last or None, messages)] in
    order; ``topics``: objects with topic, msg_type, count, best_effort, latched (e.g.
    :class:`~cvc_balance.bag.mcap_writer.TopicWritten`); ``custom_data`` {key: value}.
    A bag or file without messages starts at :data:`NEVER` and lasts 0, as rosbag2 says.
    """
    from cvc_balance.messages.msg_schema import type_hash

    def span(first, last):
        if first is None:
            return {'nanoseconds_since_epoch': NEVER}, {'nanoseconds': 0}
        return {'nanoseconds_since_epoch': int(first)}, {'nanoseconds': int(last) - int(first)}
    times = [(f, t) for _, f, t, _ in files if f is not None]
    start, duration = span(min((f for f, _ in times), default=None),
                           max((t for _, t in times), default=None))
    return {
        'version': VERSION,
        'storage_identifier': 'mcap',
        'duration': duration,
        'starting_time': start,
        'message_count': sum(t.count for t in topics),
        'topics_with_message_count': [
            {'topic_metadata': {'name': t.topic, 'type': t.msg_type,
                                'serialization_format': 'cdr',
                                'offered_qos_profiles': [qos_profile(t.best_effort, t.latched)],
                                'type_description_hash': type_hash(t.msg_type)},
             'message_count': t.count} for t in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [name for name, _, _, _ in files],
        'files': [{'path': name, 'starting_time': span(first, last)[0],
                   'duration': span(first, last)[1], 'message_count': count}
                  for name, first, last, count in files],
        'custom_data': {str(k): str(v) for k, v in custom_data.items()} if custom_data else None,
        'ros_distro': ROS_DISTRO,
    }


def metadata_yaml(metadata):
    """Return metadata.yaml's text of a :func:`bag_metadata` mapping (as rosbag2 writes it)."""
    return emit({'rosbag2_bagfile_information': metadata})


def record_values(metadata):
    """Return the ``rosbag2`` Metadata record's {key: value} of a :func:`bag_metadata` mapping."""
    return {SERIALIZED: emit(metadata)}
