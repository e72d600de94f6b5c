"""
The spin loop of the project's ROS processes (the node, ``record``): one home for it.

rclpy's experimental EventsExecutor answers faster than the default executor (p50
0.45 against 0.6 ms here); it is driven by ``spin_once`` with a timeout (see
:func:`spin`).
"""

import signal
import threading

import rclpy
from rclpy.executors import ExternalShutdownException

_stop = threading.Event()


def init(args=None):
    """
    Start rclpy for a process that spins with :func:`spin`: SIGINT and SIGTERM stop it.

    rclpy's own handlers let SIGINT raise KeyboardInterrupt wherever Python is: inside a
    callback the events executor called from C++, the exception crosses C++ and the
    process aborts (``terminate called after throwing an instance of
    'pybind11::error_already_set'``; seen: exit code -6 for a node stopped right after a
    big layout). Here a signal only sets a flag, and :func:`spin` stops between callbacks.
    """
    from rclpy.signals import SignalHandlerOptions
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, lambda *_: _stop.set())


def spin(node, on_error=None):
    """
    Spin ``node`` until SIGINT or SIGTERM (:func:`init`) or the context shuts down.

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
        while rclpy.ok(context=node.context) and not _stop.is_set():
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
