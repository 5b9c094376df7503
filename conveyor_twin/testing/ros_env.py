"""ROS 2 environment of a test session: a private DDS domain on loopback, and cleanup after it.

Every ROS process of a test run keeps its traffic on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) and in a domain of its own. The domain id is claimed
per test process: a candidate derived from the pid, taken only if an advisory lock on
``/tmp/conveyor_twin_ros_domain_<id>.lock`` can be held for the whole session, so parallel runs on
one machine (several pytest processes, CI jobs) never share a domain. The kernel drops the lock
when the process ends, so a killed run leaves nothing stale behind.

Fast DDS keeps its shared-memory transport in ``/dev/shm`` and does not remove it when a process
is killed. Observed with Fast DDS 3.2 (ros-fastdds wheel) by starting and ``kill -9``-ing
publishers:

- ``fastdds_<16 hex>`` (a participant's segment, random name) with ``fastdds_<16 hex>_el``;
- ``fastdds_port<N>`` (a listening port; senders open it too) with the semaphore
  ``sem.fastdds_port<N>_mutex`` and, while its listener lives, ``fastdds_port<N>_el`` (``_sl``);
  a sender to a port whose listener was killed re-creates the port without lock files;
- ``fast_datasharing_<guid prefix>_<entity id>`` when data sharing is on (off by default in
  Kilted), e.g. ``fast_datasharing_01.0f.78.fd.fc.10.21.d4.00.00.00.00_0.0.13.3``: octets 2-3 of
  the GUID prefix are the host id, octets 4-5 the low 16 bits of the owner's pid (little endian).

No name carries a full pid. Owners hold an ``flock`` on the ``_el``/``_sl`` files while alive (what
``fastdds shm clean`` tests); files without lock files are judged by whether a live process maps
them (``/proc/<pid>/maps``), data-sharing segments also by their pid bits. Fast DDS 2.x names
(``fastrtps_``) are handled alike. Other files (``lttng-ust-wait-*``, tracing) are left alone.
"""

import fcntl
import os
from pathlib import Path
import re
import signal
import subprocess
import tempfile
import time
from typing import Callable, Dict, IO, List, Mapping, Optional, Sequence, Set, TYPE_CHECKING

if TYPE_CHECKING:
    from rclpy.executors import Executor

# Domain ids Fast DDS can use without colliding with the ephemeral port range: 0-101 and 215-232
# (ROS 2 "The ROS_DOMAIN_ID" concept page). 0 is left out: it is the default of every ROS process.
DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
DOMAIN_LOCK_DIR = Path(tempfile.gettempdir())
DOMAIN_LOCK_PREFIX = 'conveyor_twin_ros_domain_'
SHM_DIR = Path('/dev/shm')
# A lock file younger than this may belong to a process still setting its segment up [s].
SHM_MIN_AGE = 1.0
STOP_TIMEOUT = 5.0  # grace time of a test subprocess after SIGINT, then after SIGTERM [s]
POLL_PERIOD = 0.01  # longest single wait of wait_for [s]

_SEGMENT_LOCK = re.compile(r'^(fastdds|fastrtps)_[0-9a-f]{16}_(el|sl)$')
_PORT_LOCK = re.compile(r'^(fastdds|fastrtps)_port(\d{1,5})_(el|sl)$')
_PORT = re.compile(r'^(fastdds|fastrtps)_port\d{1,5}$')
# 01.0f: eProsima's vendor id; then host id (2 octets), pid (low 16 bits, little endian), ...
_DATASHARING = re.compile(
    r'^fast_datasharing_01\.0f\.[0-9a-f]{2}\.[0-9a-f]{2}\.([0-9a-f]{2})\.([0-9a-f]{2})\.')

_domain_id: Optional[int] = None
_domain_lock: Optional[IO[str]] = None
_started: List[subprocess.Popen] = []


def claim_domain_id(pid: Optional[int] = None) -> int:
    """Claim a ROS domain id for this process for the rest of its life; return it.

    The search starts at a candidate derived from ``pid`` and takes the first id whose lock file
    nobody holds. Calling it again returns the id already claimed.

    :param pid: process id to derive the first candidate from (default: this process)
    :return: the domain id
    :raises RuntimeError: when every candidate is held by another process
    """
    global _domain_id, _domain_lock
    if _domain_id is not None:
        return _domain_id
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
        _domain_id, _domain_lock = candidate, lock
        return candidate
    msg = f'all {len(DOMAIN_IDS)} ROS domain ids are locked in {DOMAIN_LOCK_DIR}'
    raise RuntimeError(msg)


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


def ros_subprocess_env(extra: Optional[Mapping[str, str]] = None) -> Dict[str, str]:
    """Return the environment for a ROS child process of this test process.

    A copy of this process's environment with loopback discovery, this session's domain id and
    unbuffered Python output, updated with ``extra``.

    :param extra: more variables for the child
    :return: environment mapping for :class:`subprocess.Popen`
    """
    env = dict(os.environ)
    env.update({
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_DOMAIN_ID': str(claim_domain_id()),
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


class RosProcesses:
    """Start ROS child processes for a test and make sure none outlives it.

    Children run in their own session (process group), with :func:`ros_subprocess_env`; stopping
    sends SIGINT to the group (rclpy shuts down cleanly), then SIGTERM, then SIGKILL, and finally
    removes the shared memory that dead processes left.
    """

    def __init__(self) -> None:
        """Create an empty set of processes."""
        self._processes: List[subprocess.Popen] = []

    def start(self, args: Sequence[str], *, env: Optional[Mapping[str, str]] = None,
              **popen_kwargs: object) -> subprocess.Popen:
        """Start a child process in this session's ROS domain.

        :param args: command line
        :param env: extra environment variables (on top of :func:`ros_subprocess_env`)
        :param popen_kwargs: further :class:`subprocess.Popen` arguments (stdout, text, ...)
        :return: the started process
        """
        popen_kwargs.setdefault('stdin', subprocess.DEVNULL)
        process = subprocess.Popen(list(args), env=ros_subprocess_env(env),
                                   start_new_session=True, **popen_kwargs)
        self._processes.append(process)
        _started.append(process)
        return process

    def stop_all(self, timeout: float = STOP_TIMEOUT) -> None:
        """Stop every process started here, escalating signals; clean dead shared memory.

        :param timeout: grace time after each of SIGINT and SIGTERM [s]
        """
        for process in self._processes:
            stop_process(process, timeout)
        self._processes.clear()
        remove_dead_shm_files()


def stop_process(process: subprocess.Popen, timeout: float = STOP_TIMEOUT) -> Optional[int]:
    """Stop a process started in its own session, and its group; return its exit code.

    :param process: the process (started with ``start_new_session=True``)
    :param timeout: grace time after each of SIGINT and SIGTERM [s]
    :return: exit code (negative: killed by that signal)
    """
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        if process.poll() is not None:
            break
        try:
            os.killpg(process.pid, sig)
        except ProcessLookupError:
            break
        try:
            process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            continue
    code = process.wait()
    # The group may hold more members than the leader (a launcher's children).
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    for stream in (process.stdin, process.stdout, process.stderr):
        if stream is not None:
            stream.close()
    return code


def stop_all_started() -> None:
    """Stop every process any :class:`RosProcesses` of this session started and left running."""
    while _started:
        process = _started.pop()
        if process.poll() is None:
            stop_process(process)


def _lock_is_free(path: Path) -> bool:
    """Return True when nobody holds an flock on ``path`` (its owner is gone)."""
    try:
        with open(path, 'ab') as handle:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


def _old_enough(path: Path, now: float, min_age: float) -> bool:
    try:
        return now - path.stat().st_mtime >= min_age
    except FileNotFoundError:
        return False


def _owned(path: Path) -> bool:
    """Return True when ``path`` belongs to this process's user."""
    try:
        return path.stat().st_uid == os.getuid()
    except FileNotFoundError:
        return False


def _live_pids_low16() -> Set[int]:
    """Return the low 16 bits of every live process id (what a Fast DDS GUID prefix carries)."""
    return {int(name) & 0xFFFF for name in os.listdir('/proc') if name.isdigit()}


def _mapped_shm_names(shm_dir: Path) -> Set[str]:
    """Return the names of the files in ``shm_dir`` that a live process has mapped.

    Processes whose mappings this one may not read are skipped: they run as another user (or
    more privileged, like a container's init), and only files of this process's own user are
    judged by this (see :func:`dead_shm_files`): Fast DDS creates them ``rw-r--r--``, so a process
    of another user cannot use them.

    :param shm_dir: the shared-memory directory
    :return: file names
    """
    marker = f' {shm_dir}/'
    mapped: Set[str] = set()
    for pid in os.listdir('/proc'):
        if not pid.isdigit():
            continue
        try:
            with open(f'/proc/{pid}/maps') as maps:
                for line in maps:
                    if marker in line:
                        name = line.split(marker, 1)[1].strip()
                        mapped.add(name.removesuffix(' (deleted)'))
        except (FileNotFoundError, ProcessLookupError, PermissionError):
            continue
    return mapped


def dead_shm_files(shm_dir: Path = SHM_DIR, min_age: float = SHM_MIN_AGE) -> List[Path]:
    """List Fast DDS shared-memory files whose owner processes no longer exist.

    A participant segment or a listening port is dead when nobody holds an flock on its lock
    files. A port file without lock files (created by a process that only sent to it) and a
    data-sharing segment are dead when they belong to this user and no live process maps them
    (data-sharing: nor does a live process carry the pid bits of its GUID prefix).

    :param shm_dir: the shared-memory directory
    :param min_age: ignore files younger than this [s]
    :return: files safe to remove
    """
    try:
        names = set(os.listdir(shm_dir))
    except FileNotFoundError:
        return []
    now = time.time()
    dead: List[Path] = []
    port_locks: Dict[str, List[str]] = {}
    unlocked: List[str] = []
    for name in sorted(names):
        if _SEGMENT_LOCK.match(name):
            lock = shm_dir / name
            if _old_enough(lock, now, min_age) and _lock_is_free(lock):
                dead += [lock, shm_dir / name[:-3]]
        elif (match := _PORT_LOCK.match(name)):
            port_locks.setdefault(f'{match.group(1)}_port{match.group(2)}', []).append(name)
        elif _PORT.match(name) or _DATASHARING.match(name):
            unlocked.append(name)
    for port, locks in port_locks.items():
        lock_paths = [shm_dir / lock for lock in locks]
        if all(_old_enough(lock, now, min_age) and _lock_is_free(lock) for lock in lock_paths):
            dead += lock_paths + [shm_dir / port, shm_dir / f'sem.{port}_mutex']
    unlocked = [name for name in unlocked if name not in port_locks
                and _old_enough(shm_dir / name, now, min_age) and _owned(shm_dir / name)]
    if unlocked:
        mapped = _mapped_shm_names(shm_dir)
        live = _live_pids_low16()
        for name in unlocked:
            if name in mapped:
                continue
            match = _DATASHARING.match(name)
            if match is None:
                if f'sem.{name}_mutex' not in mapped:
                    dead += [shm_dir / name, shm_dir / f'sem.{name}_mutex']
            else:
                pid_low16 = int(match.group(1), 16) | (int(match.group(2), 16) << 8)
                if pid_low16 not in live:
                    dead.append(shm_dir / name)
    return [path for path in dead if path.name in names]


def remove_dead_shm_files(shm_dir: Path = SHM_DIR, min_age: float = SHM_MIN_AGE) -> List[Path]:
    """Remove the files :func:`dead_shm_files` finds; return those removed.

    :param shm_dir: the shared-memory directory
    :param min_age: ignore lock files younger than this [s]
    :return: removed files
    """
    removed = []
    for path in dead_shm_files(shm_dir, min_age):
        try:
            path.unlink()
        except FileNotFoundError:
            continue
        removed.append(path)
    return removed
