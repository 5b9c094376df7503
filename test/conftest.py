"""Session-wide test set-up: a private ROS domain on loopback for the whole test process.

The environment is configured when pytest loads this file, before any test module is imported,
so every ``rclpy`` context of the run and every child process (see
:func:`conveyor_twin.testing.ros_subprocess_env`) discovers only on this machine and only in
this run's domain. The fixtures (``conveyor_twin``, ``ros_context``, ``ros_processes``, ...) and
the cleanup after the session come from the package's pytest plugin
(:mod:`conveyor_twin.testing.plugin`, entry point ``pytest11``: ``conveyor_twin``).
"""

from conveyor_twin.testing.ros_env import configure_session

DOMAIN_ID = configure_session()


def pytest_report_header() -> str:
    """Show the run's ROS environment in pytest's header."""
    return f'ROS: ROS_DOMAIN_ID={DOMAIN_ID}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST'
