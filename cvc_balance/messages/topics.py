"""
The node's topics: names (relative, so namespaces and remapping work) and message types.

One place for them: the node publishes them, replay writes them to bags, play and
record subscribe to them.
"""

JOINT_STATES = 'joint_states'
SPEED = 'speed'
LAYOUT = 'layout'
BEARING_LOAD = 'bearing_load'
UNBALANCE = 'unbalance'
DRIVE_TORQUE = 'drive_torque'
DIAGNOSTICS = '/diagnostics'
MEASURED_LOAD = 'measured_load'
IDENTIFIED_UNBALANCE = 'identified_unbalance'
UNBALANCE_RESIDUAL = 'unbalance_residual'

JOINT_STATE_TYPE = 'sensor_msgs/msg/JointState'
FLOAT64_TYPE = 'std_msgs/msg/Float64'
STRING_TYPE = 'std_msgs/msg/String'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'
DIAGNOSTIC_ARRAY_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'

OUTPUTS = (BEARING_LOAD, UNBALANCE, DRIVE_TORQUE)
"""The outputs every layout has; each support adds :func:`support_load`."""


def support_load(name):
    """Return the topic of a support's load."""
    return f'supports/{name}/load'


def measured_load(name):
    """Return the topic of a support's load cell (WrenchStamped, stator frame, N)."""
    return f'supports/{name}/{MEASURED_LOAD}'


# Sensors of rotors without an encoder (bag/channels.py): a keyphasor and vibration channels.
KEYPHASOR = 'keyphasor'
VECTOR3_STAMPED_TYPE = 'geometry_msgs/msg/Vector3Stamped'
IMU_TYPE = 'sensor_msgs/msg/Imu'
TIME_REFERENCE_TYPE = 'sensor_msgs/msg/TimeReference'
