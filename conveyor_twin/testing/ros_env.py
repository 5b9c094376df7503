"""ROS 2 environment of a test: a private DDS domain on loopback, and bounded waits.

Every ROS process of a test run keeps its traffic on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) and in a domain of its own. A domain id is taken
only if an advisory lock on ``<tmp>/conveyor_twin_ros_domain_<id>.lock`` can be held, so parallel
runs on one machine (pytest-xdist workers, several CI jobs) never share a domain. The kernel
drops the lock when the process ends, so a killed run leaves nothing stale behind.

:func:`claim_domain_id` holds one id for the whole process (its environment, its child
processes); :func:`lease_domain_id` holds one until released (each test twin takes its own).
"""

from contextlib import contextmanager
import fcntl
import os
from pathlib import Path
import tempfile
import time
import threading
from typing import Callable, Dict, IO, Iterator, Mapping, Optional, TYPE_CHECKING

if TYPE_CHECKING:
    from rclpy.executors import Executor

# Domain ids Fast DDS can use without colliding with the ephemeral port range: 0-101 and 215-232
# (ROS 2 "The ROS_DOMAIN_ID" concept page). 0 is left out: it is the default of every ROS process.
DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
DOMAIN_LOCK_DIR = Path(tempfile.gettempdir())
DOMAIN_LOCK_PREFIX = 'conveyor_twin_ros_domain_'
POLL_PERIOD = 0.01  # longest single wait of wait_for [s]


class DomainLease:
    """A ROS domain id held through an advisory lock until :meth:`release`.

    :param domain_id: the id held
    :param lock: the open lock file whose ``flock`` holds it
    """

    def __init__(self, domain_id: int, lock: IO[str]) -> None:
        self.domain_id = domain_id
        self._lock: Optional[IO[str]] = lock

    def release(self) -> None:
        """Give the id back (other processes and leases may take it again)."""
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    def __repr__(self) -> str:
        held = 'held' if self._lock is not None else 'released'
        return f'DomainLease({self.domain_id}, {held})'


def lease_domain_id(pid: Optional[int] = None) -> DomainLease:
    """Take a ROS domain id nobody else holds (no other process, no other lease); return it.

    The search starts at a candidate derived from ``pid`` and takes the first id whose lock file
    nobody holds.

    :param pid: process id to derive the first candidate from (default: this process)
    :return: the lease; release it when done (the process's end releases it too)
    :raises RuntimeError: when every candidate is held
    """
    pid = os.getpid() if pid is None else pid
    start = pid % len(DOMAIN_IDS)
    for k in range(len(DOMAIN_IDS)):
        candidate = DOMAIN_IDS[(start + k) % len(DOMAIN_IDS)]
        path = DOMAIN_LOCK_DIR / f'{DOMAIN_LOCK_PREFIX}{candidate}.lock'
        try:
            lock = open(path, 'a')
        except OSError:
            continue
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return DomainLease(candidate, lock)
    msg = f'all {len(DOMAIN_IDS)} ROS domain ids are locked in {DOMAIN_LOCK_DIR}'
    raise RuntimeError(msg)


_process_lease: Optional[DomainLease] = None


def claim_domain_id(pid: Optional[int] = None) -> int:
    """Claim a ROS domain id for this process for the rest of its life; return it.

    Calling it again returns the id already claimed.

    :param pid: process id to derive the first candidate from (default: this process)
    :return: the domain id
    :raises RuntimeError: when every candidate is held by another process
    """
    global _process_lease
    if _process_lease is None:
        _process_lease = lease_domain_id(pid)
    return _process_lease.domain_id


def configure_session() -> int:
    """Put this process on loopback discovery in its own domain; return the domain id.

    Call before anything creates a ROS context (rcl reads both variables at ``rclpy.init`` and at
    node creation; setting them before ``import rclpy`` is the safe order).

    :return: the domain id now in ``ROS_DOMAIN_ID``
    """
    domain_id = claim_domain_id()
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['ROS_DOMAIN_ID'] = str(domain_id)
    # Neither may widen discovery beyond this machine or conflict with the range above.
    os.environ.pop('ROS_LOCALHOST_ONLY', None)
    os.environ.pop('ROS_STATIC_PEERS', None)
    return domain_id


#: rcl reads the discovery range from the environment when a context is initialised: the
#: environment is set for that moment only, under this lock, and restored at once.
_ENV_LOCK = threading.Lock()


@contextmanager
def loopback_environment() -> Iterator[None]:
    """Loopback discovery for an rclpy context initialised inside the block; this process's
    environment is as before once the block ends (rcl reads it at ``rclpy.init``)."""
    names = ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_LOCALHOST_ONLY', 'ROS_STATIC_PEERS')
    with _ENV_LOCK:
        saved = {n: os.environ.get(n) for n in names}
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        os.environ.pop('ROS_LOCALHOST_ONLY', None)
        os.environ.pop('ROS_STATIC_PEERS', None)
        try:
            yield
        finally:
            for name, value in saved.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value


def ros_subprocess_env(extra: Optional[Mapping[str, str]] = None, *,
                       domain_id: Optional[int] = None) -> Dict[str, str]:
    """Return the environment for a ROS child process of this test process.

    A copy of this process's environment with loopback discovery, the domain id and unbuffered
    Python output, updated with ``extra``.

    :param extra: more variables for the child
    :param domain_id: the child's ROS domain (default: this process's, :func:`claim_domain_id`)
    :return: environment mapping for :class:`subprocess.Popen`
    """
    env = dict(os.environ)
    env.update({
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_DOMAIN_ID': str(claim_domain_id() if domain_id is None else domain_id),
        'PYTHONUNBUFFERED': '1',
    })
    env.pop('ROS_LOCALHOST_ONLY', None)
    env.pop('ROS_STATIC_PEERS', None)
    env.update(extra or {})
    return env


def wait_for(condition: Callable[[], bool], timeout: float,
             executor: Optional['Executor'] = None) -> bool:
    """Poll ``condition`` until it holds or ``timeout`` passes; return whether it held.

    With an executor, the waiting is done by spinning it (``spin_once``), so callbacks run while
    waiting; without one, by short sleeps. No single wait exceeds :data:`POLL_PERIOD` or the time
    left.

    :param condition: predicate, evaluated at least once
    :param timeout: longest total wait [s]
    :param executor: rclpy executor to spin while waiting
    :return: True when the condition held within the timeout
    """
    deadline = time.monotonic() + timeout
    while True:
        if condition():
            return True
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            return False
        if executor is not None:
            executor.spin_once(timeout_sec=min(POLL_PERIOD, remaining))
        else:
            time.sleep(min(POLL_PERIOD, remaining))


