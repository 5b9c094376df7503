"""ROS child processes of a test: started in the test's domain, never outliving it."""

import os
import signal
import subprocess
from typing import List, Mapping, Optional, Sequence

from conveyor_twin.testing.ros_env import ros_subprocess_env
from conveyor_twin.testing.shm import remove_dead_shm_files

STOP_TIMEOUT = 5.0  # grace time of a child process after SIGINT, then after SIGTERM [s]

_started: List[subprocess.Popen] = []


class RosProcesses:
    """Start ROS child processes for a test and make sure none outlives it.

    Children run in their own session (process group), with :func:`ros_subprocess_env`; stopping
    sends SIGINT to the group (rclpy shuts down cleanly), then SIGTERM, then SIGKILL, and finally
    removes the shared memory that dead processes left.

    :param domain_id: the children's ROS domain (default: this process's)
    """

    def __init__(self, *, domain_id: Optional[int] = None) -> None:
        """Create an empty set of processes."""
        self.domain_id = domain_id
        self._processes: List[subprocess.Popen] = []

    def start(self, args: Sequence[str], *, env: Optional[Mapping[str, str]] = None,
              **popen_kwargs: object) -> subprocess.Popen:
        """Start a child process in the ROS domain of this set.

        :param args: command line
        :param env: extra environment variables (on top of :func:`ros_subprocess_env`)
        :param popen_kwargs: further :class:`subprocess.Popen` arguments (stdout, text, ...)
        :return: the started process
        """
        popen_kwargs.setdefault('stdin', subprocess.DEVNULL)
        env = ros_subprocess_env(env, domain_id=self.domain_id)
        process = subprocess.Popen(list(args), env=env, start_new_session=True, **popen_kwargs)
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
    """Stop every process any :class:`RosProcesses` started in this process and left running."""
    while _started:
        process = _started.pop()
        if process.poll() is None:
            stop_process(process)
