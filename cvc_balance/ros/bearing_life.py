"""
The node's bearing life: each described bearing's life used, live, and kept across restarts.

Every accepted motion sample's support loads go to :class:`~cvc_balance.physics.bearing_life.
LifeCounters` (O(1), plain floats: well under the rest of a sample's work). The counts go on
across layout changes while a support keeps its name and its bearing (a changed bearing
description is a new bearing: counted from 0, logged).

**Across restarts** (when the node records, ``record_path``): a small state file beside the
recording, ``bearing_life_<machine>.json`` in the recording's folder (``<machine>``: the
``machine_id``, else the node's name, in file-name characters), holds each bearing's count
(revolutions, damage, seconds of running, its bearing); it is read at start, written at
each diagnostics period and at shutdown, under a temporary name then renamed (a killed node
leaves the last one whole). The recordings themselves get new names each start, so the count
cannot live in them. A state file that cannot be read is never written over: the count
starts from 0 in memory and the status says so.

The status ``<node>: bearing life``: per bearing the life used since start and in all, its
rate (life used per hour of running: hours over which motion samples came), the rating life
and the life left at that duty, the mean equivalent load; WARN when a bearing has used its
whole rating life or the speed has passed its limiting speed.
"""

from dataclasses import asdict
from datetime import datetime, timezone
import json
import math
import os
from pathlib import Path
import re

from cvc_balance.physics import assessment
from cvc_balance.physics.bearing_life import LifeCounter, LifeCounters
from cvc_balance.physics.documents import DocumentError, read_document

KIND = 'cvc_balance bearing life'
"""The state file's ``kind`` (a reader refuses a file that is not one)."""
VERSION = 1
MAX_STATE_BYTES = 1 << 20
"""Largest state file read (a few hundred bytes per bearing)."""
COUNTS = ('revolutions', 'damage', 'seconds')


def state_path(record_path, machine):
    """Return the state file beside ``record_path`` for ``machine`` (its name, any text)."""
    safe = re.sub(r'[^A-Za-z0-9_.-]+', '_', machine).strip('._') or 'node'
    return Path(record_path).absolute().parent / f'bearing_life_{safe}.json'


def read_state(path):
    """
    Return {support name: (bearing fields dict, revolutions, damage, seconds)} of a state file.

    {} when there is none. Raises ValueError (one line) when it cannot be read or is not one.
    """
    if not os.path.lexists(path):
        return {}
    try:
        data = read_document(path, MAX_STATE_BYTES)
    except DocumentError as error:      # it names the path
        raise ValueError(str(error)) from None
    except OSError as error:
        raise ValueError(f'{path}: {error.strerror or error}') from None
    if not isinstance(data, dict) or data.get('kind') != KIND or \
            not isinstance(data.get('supports'), dict):
        raise ValueError(f"{path}: not a bearing life state file (kind '{KIND}')")
    state = {}
    for name, entry in data['supports'].items():
        counts = [entry.get(key) if isinstance(entry, dict) else None for key in COUNTS]
        if not isinstance(entry, dict) or not isinstance(entry.get('bearing'), dict) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                and v >= 0.0 for v in counts):
            raise ValueError(f'{path}: support {name!r}: give bearing and revolutions, damage, '
                             'seconds (finite, >= 0)')
        state[name] = (entry['bearing'], *map(float, counts))
    return state


class BearingLife:
    """The node's bearing life (see the module's description)."""

    def __init__(self, path=None, log=None):
        """
        Count from the state file at ``path`` (None: no state kept).

        ``log(severity, text)`` logs (the node's). An unreadable file is kept as it is.
        """
        self.path, self.log = path, log or (lambda severity, text: None)
        self.problem = ''
        self.counting = None        # the LifeCounters of the layout in force (None: none)
        self.stored = {}            # support name -> LifeCounter, every bearing seen or read
        self.base = {}              # support name -> (revolutions, damage, seconds) at start
        self._read = {}
        if path is not None:
            try:
                self._read = read_state(path)
            except ValueError as error:
                self.problem = (f'state file unreadable, not written over (counted from 0 '
                                f'since start): {error}')
                self.log('error', f'bearing life: {self.problem}')
                self.path = None

    def layout(self, supports):
        """Count the bearings of a layout put in force (its ``supports``)."""
        for support in supports:
            bearing = support.bearing
            if bearing is None:
                continue
            known = self.stored.get(support.name)
            if known is not None and known.bearing != bearing:
                self.log('warning', f'bearing life: support {support.name} has another bearing '
                         'now: counted from 0')
                self.stored.pop(support.name)
                self.base[support.name] = (0.0, 0.0, 0.0)
            if support.name in self.stored:
                continue
            read = self._read.pop(support.name, None)
            counts = (0.0, 0.0, 0.0)
            if read is not None:
                if read[0] == asdict(bearing):
                    counts = read[1:]
                else:
                    self.log('warning', f'bearing life: support {support.name}: the state file '
                             'holds another bearing: counted from 0')
            self.stored[support.name] = LifeCounter(support.name, bearing, *counts)
            self.base.setdefault(support.name, counts)
        previous = self.counting
        if previous is not None:
            previous.flush()
        # The stored counters go on: a support that keeps its name and bearing keeps its count.
        counting = LifeCounters(supports, self.stored,
                                previous.last if previous is not None else None)
        self.counting = counting if counting else None

    def restart(self):
        """Forget the last sample (a new time line)."""
        if self.counting is not None:
            self.counting.restart()

    def save(self):
        """Write the state file (if kept): under a temporary name, then renamed."""
        if self.path is None or not self.stored:
            return
        if self.counting is not None:
            self.counting.flush()
        data = {'kind': KIND, 'version': VERSION,
                'saved_utc': datetime.now(timezone.utc).isoformat().replace('+00:00', 'Z'),
                'supports': {name: {'bearing': asdict(c.bearing), 'revolutions': c.revolutions,
                                    'damage': c.damage, 'seconds': c.seconds,
                                    'life_used': c.use().life_used}
                             for name, c in self.stored.items()}}
        for name, read in self._read.items():      # bearings of layouts not seen this run
            data['supports'].setdefault(name, {'bearing': read[0], **dict(zip(COUNTS,
                                                                              read[1:]))})
        temporary = self.path.with_name(f'.{self.path.name}.{os.getpid()}.tmp')
        try:
            with open(temporary, 'w', encoding='utf-8') as stream:
                json.dump(data, stream, indent=1)
            os.replace(temporary, self.path)
        except OSError as error:
            self.problem = f'state file not written: {error.strerror}: {self.path}'
            self.log('error', f'bearing life: {self.problem}')

    def status(self, top_speed):
        """
        Return (level, message, values) of the bearings in force, or None: none described.

        Levels of :mod:`cvc_balance.physics.assessment`; ``top_speed`` rad/s (the top
        |omega| seen under the layout in force).
        """
        if self.counting is None:
            return None
        self.counting.flush()
        level, parts, warnings, values = assessment.OK, [], [], {}
        for name, counter in self.counting.counters.items():
            now = counter.use()
            start = self.base.get(name, (0.0, 0.0, 0.0))
            since = type(now)(counter.bearing, now.revolutions - start[0],
                              now.damage - start[1], now.seconds - start[2])
            duty = since if since.seconds > 0.0 else now
            rate = duty.rate
            left = None if not rate else max(1.0 - now.life_used, 0.0) / rate
            load = since.equivalent_load
            values.update({
                f'{name} life used since start': since.life_used,
                f'{name} life used in all': now.life_used,
                f'{name} life used per hour of running': rate if rate is not None else '',
                f'{name} rating life at this duty [h]': duty.rating_life_hours or '',
                f'{name} life left at this duty [h]': left if left is not None else '',
                f'{name} mean equivalent load since start [N]': load if load else '',
                f'{name} revolutions since start': since.revolutions,
                f'{name} hours of running since start': since.hours})
            text = f'{name} {since.life_used:.3g} used since start'
            if rate:
                text += f' ({rate:.3g}/h: rating life {1.0 / rate:.4g} h at this duty)'
            parts.append(text + f', {now.life_used:.3g} in all')
            if now.life_used >= 1.0:
                warnings.append(f'{name} has used its whole rating life '
                                f'({now.life_used:.3g})')
            limit = counter.bearing.limit_speed
            if limit is not None and top_speed > limit:
                warnings.append(f'{name}: speed {top_speed:.4g} rad/s over its limiting speed '
                                f'{limit:.4g} rad/s')
        values['state file'] = str(self.path) if self.path is not None else (
            self.problem or 'none (the node does not record: counted since start)')
        if warnings:
            level = assessment.WARN
        message = 'bearing life: ' + '; '.join(warnings + parts)
        return level, message, values
