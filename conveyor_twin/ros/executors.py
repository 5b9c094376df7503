"""The rclpy executors the twin's processes spin their nodes with."""

import threading

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException


def make_executor(context: Context):
    """Return rclpy's EventsExecutor (about 3x less CPU) or, if absent, a single-threaded one."""
    try:
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    except ImportError:  # pragma: no cover - older rclpy
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)


def spin_until(executor, stop: threading.Event, period: float = 0.05) -> None:
    """Serve callbacks until ``stop`` is set (rclpy 9.1's EventsExecutor.spin() cannot be
    ended by ``shutdown()`` from another thread; bounded spin_once calls can)."""
    try:
        while not stop.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=period)
    except (ExternalShutdownException, rclpy.executors.ShutdownException):
        pass
