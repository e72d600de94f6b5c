"""
Which topics of a bag are the node's inputs: the motion and the layout.

By default the node's own (relative) names, found at the root or under one
namespace (``/gantry/joint_states``) if exactly one topic has that name; the
user names others (remapped topics) with ``--joint-states``, ``--speed-topic``,
``--keyphasor`` and ``--layout-topic``, matched exactly. The motion comes from the
one named, else from joint_states, else speed, else a keyphasor topic
``keyphasor`` (a once-per-revolution tach: :mod:`cvc_balance.bag.channels`).
Used by replay, identify, view and play.
"""

from dataclasses import dataclass

from cvc_balance.bag.channels import keyphasor_channel
from cvc_balance.bag.mcap_reader import BagError, describe_topics
from cvc_balance.messages import topics

OPTIONS = {'joint_states': '--joint-states', 'speed': '--speed-topic', 'layout': '--layout-topic',
           'keyphasor': '--keyphasor'}
"""The command-line option that names each input topic."""


@dataclass(frozen=True)
class InputTopics:
    """
    Topic names of the inputs in a bag; None: the node's own name (see the module).

    ``keyphasor_edge`` and ``keyphasor_threshold`` (the signal's unit; None: midway
    between its levels) apply to a sampled tach (std_msgs/Float64).
    """

    joint_states: str = None
    speed: str = None
    layout: str = None
    keyphasor: str = None
    keyphasor_edge: str = 'rising'
    keyphasor_threshold: float = None


@dataclass
class InputChannels:
    """The bag's channels of the inputs: motion (JointState, speed or keyphasor), layout."""

    joint_states: object = None
    speed: object = None
    layout: object = None
    keyphasor: object = None

    @property
    def motion(self):
        """Return the channel the motion comes from (the one found: see the module)."""
        return self.joint_states or self.speed or self.keyphasor


def input_channels(bag, names=None):
    """
    Return the :class:`InputChannels` of ``bag`` for ``names`` (:class:`InputTopics`).

    A keyphasor named is used (and nothing else for the motion); else joint_states
    unless only --speed-topic was given; else speed; else a keyphasor topic ``keyphasor``.
    Raises :class:`BagError` naming the bag's topics and types when a named topic is
    missing or has another type, or when the bag has no motion topic.
    """
    names = names or InputTopics()
    found = InputChannels()
    if names.keyphasor is not None:
        if names.joint_states is not None or names.speed is not None:
            raise BagError(f'{bag.path}: --keyphasor is the motion: give it without '
                           '--joint-states or --speed-topic')
        found.keyphasor = keyphasor_channel(bag, names.keyphasor)
    else:
        use_joints = names.joint_states is not None or names.speed is None
        if use_joints:
            found.joint_states = _channel(bag, names.joint_states, 'joint_states',
                                          topics.JOINT_STATE_TYPE)
        if found.joint_states is None:
            found.speed = _channel(bag, names.speed, 'speed', topics.FLOAT64_TYPE)
        if found.motion is None and names.joint_states is None and names.speed is None:
            found.keyphasor = _default_keyphasor(bag)
    if found.motion is None:
        raise BagError(f'{bag.path}: no {topics.JOINT_STATES} ({topics.JOINT_STATE_TYPE}), '
                       f'{topics.SPEED} ({topics.FLOAT64_TYPE}) or {topics.KEYPHASOR} '
                       f'({topics.FLOAT64_TYPE} or {topics.TIME_REFERENCE_TYPE}) topic; the '
                       f'bag has: {describe_topics(bag.channels.values())} (name the topic '
                       'with --joint-states, --speed-topic or --keyphasor)')
    found.layout = _channel(bag, names.layout, 'layout', topics.STRING_TYPE)
    return found


def _default_keyphasor(bag):
    """Return the bag's ``keyphasor`` topic (as :func:`keyphasor_channel` finds it), or None."""
    wanted = topics.KEYPHASOR
    if not any(c.topic.strip('/') == wanted or c.topic.endswith('/' + wanted)
               for c in bag.channels.values()):
        return None
    return keyphasor_channel(bag)


def _channel(bag, given, name, msg_type):
    """Find the channel of input ``name``: the node's name by default, else the one ``given``."""
    if given is None:
        return bag.channel(getattr(topics, name.upper()), msg_type, OPTIONS[name])
    channel = bag.channel(given, msg_type, OPTIONS[name], exact=True)
    if channel is None:
        raise BagError(f'{bag.path}: no topic {given} (given with {OPTIONS[name]}); the bag '
                       f'has: {describe_topics(bag.channels.values())}')
    return channel
