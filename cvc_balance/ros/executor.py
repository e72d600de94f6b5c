"""
The spin loop of the project's ROS processes (the node, ``record``): one home for it.

rclpy's experimental EventsExecutor answers faster than the default executor (p50
0.45 against 0.6 ms here); it is driven by ``spin_once`` with a timeout (see
:func:`spin`).
"""

import rclpy
from rclpy.executors import ExternalShutdownException


def spin(node, on_error=None):
    """
    Spin ``node`` until the context shuts down (SIGINT, SIGTERM): the events executor.

    rclpy's experimental EventsExecutor answers faster than the default one; its
    spin() busy-waits holding the GIL in this rclpy (7.1), so it is driven by
    spin_once with a timeout, which also lets the signal handlers stop it.

    A message rclpy itself cannot hand over (a std_msgs/String that is no UTF-8 makes
    spin_once raise) is lost, not the process: ``on_error(error)`` is told, and spinning
    goes on.
    """
    try:
        from rclpy.experimental import EventsExecutor
        executor = EventsExecutor(context=node.context)
    except ImportError:  # an rclpy without it: the default executor
        executor = rclpy.executors.SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while rclpy.ok(context=node.context):
            try:
                executor.spin_once(timeout_sec=0.1)
            except (KeyboardInterrupt, ExternalShutdownException):
                raise
            except Exception as error:       # one message lost, not the node
                if on_error is None:
                    raise
                on_error(error)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
