"""pytest plugin ``conveyor_twin`` (entry point ``pytest11``): fixtures for controller tests.

Fixtures:

- ``conveyor_twin``: a :class:`~conveyor_twin.testing.LockstepTwin` of the default cell, seed 0,
  composed layout; closed after the test, pass or fail;
- ``conveyor_twin_factory``: ``make(cell=None, *, seed=0, layout='composed', chunk=10)`` returns
  a started twin; every twin it made is closed after the test;
- ``ros_context``, ``ros_executor``, ``ros_processes``: a private rclpy context, an executor on
  it, and a starter of ROS child processes that stops them all after the test.

Every twin takes a ROS domain id of its own (a lock no other process or twin holds) and
discovers on loopback only, so pytest-xdist workers never see each other's traffic. After the
session, child processes left running are stopped and the Fast DDS shared memory of dead
processes is removed from ``/dev/shm``. Nothing here imports rclpy before a fixture runs.
"""

from typing import Any, Callable, Iterator, List, TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from conveyor_twin.testing.harness import LockstepTwin
    from conveyor_twin.testing.processes import RosProcesses


def pytest_configure(config: pytest.Config) -> None:
    """Register the marker of tests that use ROS."""
    config.addinivalue_line('markers', 'ros: uses ROS 2 (DDS traffic on loopback, own domain)')


def pytest_sessionstart(session: pytest.Session) -> None:
    """Remove shared memory left in /dev/shm by killed ROS processes of earlier runs."""
    from conveyor_twin.testing.shm import remove_dead_shm_files
    remove_dead_shm_files()


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Stop child processes a test left running; remove the shared memory of dead ones."""
    from conveyor_twin.testing.processes import stop_all_started
    from conveyor_twin.testing.shm import remove_dead_shm_files
    stop_all_started()
    remove_dead_shm_files()


@pytest.fixture
def conveyor_twin_factory() -> Iterator[Callable[..., 'LockstepTwin']]:
    """Yield ``make(cell=None, *, seed=0, layout='composed', chunk=10, timeout=60)``, which
    starts a lockstep twin; every twin made is closed after the test."""
    from conveyor_twin.testing.harness import LockstepTwin

    twins: List[LockstepTwin] = []

    def make(cell: Any = None, **kwargs: Any) -> LockstepTwin:
        twin = LockstepTwin(cell, **kwargs)
        twins.append(twin)
        return twin

    try:
        yield make
    finally:
        # a background failure after the test's last call still fails the test
        late = [f for f in (t.unreported_failures() for t in twins) if f is not None]
        for twin in reversed(twins):
            twin.close()
    if late:
        raise late[0]


@pytest.fixture
def conveyor_twin(conveyor_twin_factory: Callable[..., 'LockstepTwin']) -> 'LockstepTwin':
    """A lockstep twin of the default cell (seed 0, composed layout), closed after the test."""
    return conveyor_twin_factory()


@pytest.fixture
def ros_context() -> Iterator['Context']:
    """Yield a private, initialised rclpy context in this process's domain (loopback
    discovery); shut it down after."""
    import os

    from conveyor_twin.testing.ros_env import claim_domain_id, configure_session

    if os.environ.get('ROS_DOMAIN_ID') != str(claim_domain_id()):
        configure_session()
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    # No rclpy signal handlers: Ctrl-C stays pytest's.
    rclpy.init(context=context, domain_id=claim_domain_id(),
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
def ros_processes() -> Iterator['RosProcesses']:
    """Yield a starter of ROS child processes in this process's domain; stop them all and
    clean /dev/shm after."""
    from conveyor_twin.testing.processes import RosProcesses

    processes = RosProcesses()
    try:
        yield processes
    finally:
        processes.stop_all()
