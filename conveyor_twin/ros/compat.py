"""What differs between the supported ROS 2 distros' rclpy, in one place.

Jazzy Jalisco ships rclpy 7.1, Kilted Kaiju rclpy 9.1. The nodes make their executors and futures
and serve callbacks through the functions here, which use only what both have; everything else of
rclpy the package uses is the same in both. A future difference is branched on here, nowhere else.
"""

import threading
from typing import Any

from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, ShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.task import Future


def make_executor(context: Context) -> Any:
    """Return the executor the nodes are served with: rclpy's EventsExecutor.

    It costs about a third of the CPU of the SingleThreadedExecutor; Jazzy's rclpy 7.1 and
    Kilted's rclpy 9.1 both have it (``rclpy.experimental``).

    :param context: an initialised rclpy Context.
    """
    return EventsExecutor(context=context)


def make_future(executor: Any) -> Future:
    """Return a Future bound to ``executor`` (rclpy 9 has ``Executor.create_future``, rclpy 7 not).

    :param executor: the executor that will complete the future's callbacks.
    """
    return Future(executor=executor)


def spin_until(executor: Any, stop: threading.Event, period: float = 0.05) -> None:
    """Serve callbacks until ``stop`` is set or the context shuts down.

    Bounded ``spin_once`` calls in a loop, because rclpy 9.1's EventsExecutor.spin() cannot be
    ended by ``shutdown()`` from another thread.

    :param executor: an executor from :func:`make_executor`.
    :param stop: set by another thread to end serving.
    :param period: longest wait of one ``spin_once`` [s].
    """
    try:
        while not stop.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=period)
    except (ExternalShutdownException, ShutdownException):
        pass
