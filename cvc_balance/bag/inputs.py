"""
Which topics of a bag are the node's inputs: joint_states or speed, and layout.

By default the node's own (relative) names, found at the root or under one
namespace (``/gantry/joint_states``) if exactly one topic has that name; the
user names others (remapped topics) with ``--joint-states``, ``--speed`` and
``--layout``, matched exactly. Used by replay, view and play.
"""

from dataclasses import dataclass

from cvc_balance.bag.mcap_reader import BagError, describe_topics
from cvc_balance.messages import topics

OPTIONS = {'joint_states': '--joint-states', 'speed': '--speed', 'layout': '--layout'}
"""The command-line option that names each input topic."""


@dataclass(frozen=True)
class InputTopics:
    """Topic names of the inputs in a bag; None: the node's own name (see the module)."""

    joint_states: str = None
    speed: str = None
    layout: str = None


@dataclass
class InputChannels:
    """The bag's channels of the inputs: motion (JointState or Float64 speed) and layout."""

    joint_states: object = None
    speed: object = None
    layout: object = None

    @property
    def motion(self):
        """Return the channel the motion comes from (joint_states if there is one)."""
        return self.joint_states or self.speed


def input_channels(bag, names=None):
    """
    Return the :class:`InputChannels` of ``bag`` for ``names`` (:class:`InputTopics`).

    joint_states is used unless only --speed was given. Raises :class:`BagError`
    naming the bag's topics and types when a named topic is missing or has
    another type, or when the bag has neither motion topic.
    """
    names = names or InputTopics()
    found = InputChannels()
    use_joints = names.joint_states is not None or names.speed is None
    if use_joints:
        found.joint_states = _channel(bag, names.joint_states, 'joint_states',
                                      topics.JOINT_STATE_TYPE)
    if found.joint_states is None:
        found.speed = _channel(bag, names.speed, 'speed', topics.FLOAT64_TYPE)
    if found.motion is None:
        raise BagError(f'{bag.path}: no {topics.JOINT_STATES} ({topics.JOINT_STATE_TYPE}) or '
                       f'{topics.SPEED} ({topics.FLOAT64_TYPE}) topic; the bag has: '
                       f'{describe_topics(bag.channels.values())} (name the topic with '
                       '--joint-states or --speed)')
    found.layout = _channel(bag, names.layout, 'layout', topics.STRING_TYPE)
    return found


def _channel(bag, given, name, msg_type):
    """Find the channel of input ``name``: the node's name by default, else the one ``given``."""
    if given is None:
        return bag.channel(getattr(topics, name.upper()), msg_type, OPTIONS[name])
    channel = bag.channel(given, msg_type, OPTIONS[name], exact=True)
    if channel is None:
        raise BagError(f'{bag.path}: no topic {given} (given with {OPTIONS[name]}); the bag '
                       f'has: {describe_topics(bag.channels.values())}')
    return channel
