"""Session-wide test set-up: a private ROS domain on loopback, ROS fixtures, cleanup.

The environment is configured when pytest loads this file, before any test module is imported,
so every ``rclpy`` context of the run and every child process (see :func:`ros_subprocess_env`)
discovers only on this machine and only in this run's domain.
"""

from typing import Iterator, TYPE_CHECKING

import pytest

from .ros_env import configure_session, remove_dead_shm_files, RosProcesses, stop_all_started

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

DOMAIN_ID = configure_session()


def pytest_report_header() -> str:
    """Show the run's ROS environment in pytest's header."""
    return f'ROS: ROS_DOMAIN_ID={DOMAIN_ID}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST'


def pytest_sessionstart() -> None:
    """Remove shared memory left in /dev/shm by killed ROS processes of earlier runs."""
    remove_dead_shm_files()


def pytest_sessionfinish() -> None:
    """Stop child processes a test left running; remove the shared memory of dead ones."""
    stop_all_started()
    remove_dead_shm_files()


@pytest.fixture
def ros_context() -> Iterator['Context']:
    """Yield a private, initialised rclpy context in the session's domain; shut it down after."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    # No rclpy signal handlers: Ctrl-C stays pytest's.
    rclpy.init(context=context, domain_id=DOMAIN_ID,
               signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


@pytest.fixture
def ros_executor(ros_context: 'Context') -> Iterator['SingleThreadedExecutor']:
    """Yield one executor on ``ros_context``; destroy its nodes and shut it down after."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=ros_context)
    try:
        yield executor
    finally:
        nodes = executor.get_nodes()
        executor.shutdown(timeout_sec=5.0)
        for node in nodes:
            node.destroy_node()


@pytest.fixture
def ros_processes() -> Iterator[RosProcesses]:
    """Yield a starter of ROS child processes; stop them all and clean /dev/shm after."""
    processes = RosProcesses()
    try:
        yield processes
    finally:
        processes.stop_all()
