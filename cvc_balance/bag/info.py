"""
``cvc-balance info BAG``: what ``ros2 bag info`` prints of a bag, and the machine and layouts.

``ros2 bag`` cannot be installed from the wheels this project runs on, so this prints
what Jazzy's ``ros2 bag info`` prints (rosbag2_py's ``format_bag_meta_data``: files, bag
size, storage id, ROS distro, duration, start and end in local time, messages, a line per
topic with its type, count and serialization format, services), then the machine the bag
was recorded on (:mod:`cvc_balance.bag.machine`), the run of a field-balancing visit it is
(:mod:`cvc_balance.bag.run_label`) and the layouts it carries (name,
digest, when each came into force). Counts and times are what this project's reader
reads of the messages (a damaged or killed recording: what can be read, its problems
said), not what a summary claims; the ROS distro is that of rosbag2's last ``rosbag2``
record (or metadata.yaml's), ``unknown`` when none says.
"""

from dataclasses import dataclass, field
from pathlib import Path
import time

import numpy as np

from cvc_balance.bag.machine import bag_custom_data, MACHINE_ID
from cvc_balance.bag.mcap_reader import Bag, string_samples
from cvc_balance.bag.rosbag2 import MAX_METADATA_BYTES, METADATA, open_bag, PartsBag, RosbagsBag
from cvc_balance.bag.rosbag2_metadata import RECORD, SERIALIZED
from cvc_balance.bag.run_label import label_of
from cvc_balance.messages import topics
from cvc_balance.physics.documents import load_document, read_document

INDENT = 19
"""ros2 bag info's column of values: its longest label ('Topic information: ') plus one."""


@dataclass
class TopicInfo:
    """A topic of the bag: its type, messages read, serialization format."""

    topic: str
    msg_type: str
    count: int
    serialization_format: str

    @property
    def service_event(self):
        """Whether this is a service's event topic (rosbag2_cpp's is_service_event_topic)."""
        return self.topic.endswith('/_service_event') and '/srv/' in self.msg_type and \
            self.msg_type.endswith('_Event')


@dataclass
class LayoutInfo:
    """A layout message of the bag: when (log time ns), its name and digest, or why rejected."""

    log_time: int
    name: str = ''
    digest: str = ''
    rejected: str = ''


@dataclass
class BagInfo:
    """What :func:`bag_info` found (see the module's description)."""

    path: str
    files: list
    size: int
    storage: str
    ros_distro: str
    start: int = None           # ns, None without messages
    end: int = None
    topics: list = field(default_factory=list)
    machine_id: str = None
    run: object = None          # bag.run_label.RunLabel, None: unlabelled
    layouts: list = field(default_factory=list)
    problems: list = field(default_factory=list)

    @property
    def messages(self):
        """Return the number of messages read, service events aside (as ros2 bag info)."""
        return sum(t.count for t in self.topics if not t.service_event)

    @property
    def duration(self):
        """Return end minus start (ns), 0 without messages."""
        return 0 if self.start is None else self.end - self.start


def bag_info(path):
    """Return the :class:`BagInfo` of a bag file or rosbag2 directory (BagError if none)."""
    bag = open_bag(path)
    parts = bag.parts if isinstance(bag, PartsBag) else [bag]
    files = [Path(p.path) for p in parts]
    info = BagInfo(str(path), [f.name for f in files], sum(_size(f) for f in files),
                   'sqlite3' if any(isinstance(p, RosbagsBag) for p in parts) else 'mcap',
                   _ros_distro(Path(path), parts))
    first, last = [], []
    for channel in bag.channels.values():
        count = 0
        for records, offsets in bag.message_offsets(channel):
            if len(offsets):
                stamps = _log_times(records, offsets)
                first.append(int(stamps.min()))
                last.append(int(stamps.max()))
                count += len(offsets)
        info.topics.append(TopicInfo(channel.topic, channel.msg_type, count,
                                     channel.encoding or 'cdr'))
    if first:
        info.start, info.end = min(first), max(last)
    found = bag_custom_data(path)
    info.machine_id = found.get(MACHINE_ID)
    info.run, label_problem = label_of(found)
    info.layouts = _layouts(bag)
    info.problems = list(bag.problems) + ([label_problem] if label_problem else [])
    return info


def _log_times(records, offsets):
    """Log times (ns) of the message records at ``offsets`` of a uint8 buffer."""
    where = np.asarray(offsets, np.int64)[:, None] + 15 + np.arange(8)
    return records[where].copy().view('<u8').ravel()


def _size(path):
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _ros_distro(path, parts):
    """Return the ROS distro rosbag2 wrote: metadata.yaml's, else the last rosbag2 record's."""
    directory = path if path.is_dir() else path.parent if path.name == METADATA else None
    if directory is not None:
        try:
            info = read_document(directory / METADATA, MAX_METADATA_BYTES)
            distro = info['rosbag2_bagfile_information'].get('ros_distro')
            if distro:
                return str(distro)
        except Exception:   # absent, unreadable, not rosbag2's: the files may say
            pass
    for part in reversed(parts):
        if not isinstance(part, Bag):
            continue
        for _, name, values, _ in reversed(part.metadata):
            if name != RECORD:
                continue
            try:
                distro = load_document(values.get(SERIALIZED, '')).get('ros_distro')
            except Exception:   # a damaged record: an earlier one may say
                continue
            if distro:
                return str(distro)
    return ''


def _layouts(bag):
    """[LayoutInfo] of the bag's layout topic (std_msgs/String named 'layout'), in time order."""
    from cvc_balance.physics.layout import LayoutError
    from cvc_balance.physics.layout_file import layout_from_text
    out = []
    for channel in bag.channels.values():
        if channel.topic.rsplit('/', 1)[-1] != topics.LAYOUT or \
                channel.msg_type != topics.STRING_TYPE:
            continue
        for log_time, text in string_samples(bag, channel):
            try:
                layout = layout_from_text(text, source='layout message')
                out.append(LayoutInfo(log_time, layout.name, layout.digest()))
            except (LayoutError, ValueError) as error:
                out.append(LayoutInfo(log_time, rejected=str(error).splitlines()[0][:200]))
    return sorted(out, key=lambda layout: layout.log_time)


def seconds(ns):
    """Return ns as ros2 bag info writes seconds: '1.000500000' (whole seconds and nine digits)."""
    whole, part = divmod(int(ns), 1_000_000_000)
    return f'{whole}.{part:09d}'


def moment(ns):
    """Return a time as ros2 bag info writes it: 'Jan  1 1970 01:00:00.999500000 (0.999500000)'."""
    whole, part = divmod(int(ns), 1_000_000_000)
    local = time.localtime(whole)
    return (f'{time.strftime("%b", local)} {local.tm_mday:2d} {local.tm_year} '
            f'{time.strftime("%H:%M:%S", local)}.{part:09d} ({seconds(ns)})')


def file_size(size):
    """Return a size as ros2 bag info writes it: '241.6 KiB' (bytes without decimals)."""
    units, index, value = ('B', 'KiB', 'MiB', 'GiB', 'TiB'), 0, float(size)
    while value >= 1024 and index < 4:
        value /= 1024
        index += 1
    return f'{value:.{0 if index == 0 else 1}f} {units[index]}'


def format_info(info):
    """Return the text of ``cvc-balance info`` (``ros2 bag info``'s lines, then ours)."""
    pad = ' ' * INDENT
    lines = ['', 'Files:             ' + (f'\n{pad}'.join(info.files)),
             f'Bag size:          {file_size(info.size)}',
             f'Storage id:        {info.storage}',
             f'ROS Distro:        {info.ros_distro or "unknown"}',
             f'Duration:          {seconds(info.duration)}s',
             f'Start:             {moment(info.start) if info.start is not None else "none"}',
             f'End:               {moment(info.end) if info.end is not None else "none"}',
             f'Messages:          {info.messages}']
    described = [f'Topic: {t.topic} | Type: {t.msg_type} | Count: {t.count} | '
                 f'Serialization Format: {t.serialization_format}'
                 for t in info.topics if not t.service_event]
    lines.append('Topic information: ' + f'\n{pad}'.join(described))
    services = [f'Service: {t.topic.removesuffix("/_service_event")} | '
                f'Type: {t.msg_type.removesuffix("_Event")} | Event Count: {t.count} | '
                f'Serialization Format: {t.serialization_format}'
                for t in info.topics if t.service_event]
    lines += [f'Service:           {len(services)}',
              'Service information: ' + f'\n{pad}  '.join(services)]
    lines.append(f'Machine id:        {info.machine_id or "none"}')
    lines.append(f'Run:               {info.run.describe() if info.run else "not labelled"}')
    layouts = [f'{layout.name} {layout.digest} from {seconds(layout.log_time)}'
               if not layout.rejected else
               f'rejected at {seconds(layout.log_time)}: {layout.rejected}'
               for layout in info.layouts]
    lines.append('Layouts:           ' + (f'\n{pad}'.join(layouts) or 'none'))
    lines += [f'problem: {problem}' for problem in info.problems]
    return '\n'.join(lines)


def info_record(info):
    """Return ``cvc-balance info --json``'s object (times in ns; the docs' "JSON outputs")."""
    return {
        'path': info.path, 'files': info.files, 'bag_size': info.size,
        'storage_identifier': info.storage, 'ros_distro': info.ros_distro or None,
        'duration_ns': info.duration, 'start_ns': info.start, 'end_ns': info.end,
        'message_count': info.messages,
        'topics': [{'name': t.topic, 'type': t.msg_type, 'count': t.count,
                    'serialization_format': t.serialization_format}
                   for t in info.topics if not t.service_event],
        'services': [{'name': t.topic.removesuffix('/_service_event'),
                      'type': t.msg_type.removesuffix('_Event'), 'event_count': t.count,
                      'serialization_format': t.serialization_format}
                     for t in info.topics if t.service_event],
        'machine_id': info.machine_id,
        'run': info.run.mapping() if info.run else None,
        'layouts': [{'log_time_ns': layout.log_time, 'name': layout.name or None,
                     'digest': layout.digest or None, 'rejected': layout.rejected or None}
                    for layout in info.layouts],
        'problems': info.problems,
    }
