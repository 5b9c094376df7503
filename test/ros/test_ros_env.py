"""The test session's ROS environment: private domain, bounded waits, /dev/shm cleanup."""

import fcntl
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any, Dict, Set

import pytest

from conveyor_twin.testing.ros_env import (claim_domain_id, DOMAIN_IDS, DOMAIN_LOCK_DIR,
                                           DOMAIN_LOCK_PREFIX, lease_domain_id,
                                           ros_subprocess_env, wait_for)
from conveyor_twin.testing.shm import dead_shm_files, remove_dead_shm_files, SHM_DIR

ECHO_SCRIPT = Path(__file__).with_name('echo_subscriber.py')
CHILD_TIMEOUT = 60.0  # start and discovery of a child process [s]


def test_session_runs_in_a_claimed_private_domain() -> None:
    domain_id = claim_domain_id()
    assert domain_id in DOMAIN_IDS
    assert os.environ['ROS_DOMAIN_ID'] == str(domain_id)
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    env = ros_subprocess_env({'EXTRA': '1'})
    assert env['ROS_DOMAIN_ID'] == str(domain_id)
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST' and env['EXTRA'] == '1'
    # Another process cannot take the same domain while this one lives.
    lock = DOMAIN_LOCK_DIR / f'{DOMAIN_LOCK_PREFIX}{domain_id}.lock'
    probe = ('import fcntl, sys\n'
             'handle = open(sys.argv[1], "a")\n'
             'try:\n'
             '    fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)\n'
             'except OSError:\n'
             '    sys.exit(3)\n')
    result = subprocess.run([sys.executable, '-c', probe, str(lock)], timeout=CHILD_TIMEOUT)
    assert result.returncode == 3


def test_leases_hold_distinct_domains_until_released() -> None:
    first, second = lease_domain_id(), lease_domain_id()
    try:
        held = {claim_domain_id(), first.domain_id, second.domain_id}
        assert len(held) == 3 and held <= set(DOMAIN_IDS)
        taken = first.domain_id
        first.release()
        again = lease_domain_id(pid=DOMAIN_IDS.index(taken))  # search starts at the freed id
        assert again.domain_id == taken
        again.release()
    finally:
        first.release()
        second.release()


def test_wait_for_is_bounded() -> None:
    start = time.monotonic()
    assert not wait_for(lambda: False, 0.2)
    assert 0.2 <= time.monotonic() - start < 2.0
    calls = []
    assert wait_for(lambda: calls.append(1) or len(calls) >= 3, 5.0)
    assert len(calls) == 3


def _free_pid_low16() -> int:
    """Return 16 pid bits that no live process carries."""
    live = {int(name) & 0xFFFF for name in os.listdir('/proc') if name.isdigit()}
    return next(bits for bits in range(1, 0x10000) if bits not in live)


def test_dead_shm_files_by_lock_mapping_and_pid(tmp_path: Path) -> None:
    def make(name: str) -> Path:
        path = tmp_path / name
        path.write_bytes(b'\0' * 64)
        os.utime(path, (time.time() - 60.0, time.time() - 60.0))
        return path

    live_segment = make('fastdds_00112233445566aa')
    live_lock = make('fastdds_00112233445566aa_el')
    dead_segment = make('fastdds_00112233445566bb')
    dead_lock = make('fastdds_00112233445566bb_el')
    dead_port = [make('fastdds_port7411'), make('fastdds_port7411_el'),
                 make('sem.fastdds_port7411_mutex')]
    orphan_port = [make('fastdds_port7663'), make('sem.fastdds_port7663_mutex')]
    pid = os.getpid()
    mine = make(f'fast_datasharing_01.0f.78.fd.{pid & 0xFF:02x}.{pid >> 8 & 0xFF:02x}'
                '.21.d4.00.00.00.00_0.0.13.3')
    gone = _free_pid_low16()
    orphan_sharing = make(f'fast_datasharing_01.0f.78.fd.{gone & 0xFF:02x}.{gone >> 8:02x}'
                          '.21.d4.00.00.00.00_0.0.14.4')
    young_lock = tmp_path / 'fastdds_00112233445566cc_el'
    young_lock.touch()
    other = make('lttng-ust-wait-6')

    with open(live_lock, 'ab') as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        dead = set(dead_shm_files(tmp_path))
        assert dead == {dead_segment, dead_lock, *dead_port, *orphan_port, orphan_sharing}
        assert set(remove_dead_shm_files(tmp_path)) == dead
    assert sorted(tmp_path.iterdir()) == sorted(
        [live_segment, live_lock, mine, young_lock, other])


def _flocks_by_pid() -> Dict[int, Set[int]]:
    """Map pid -> inodes it holds FLOCKs on, from /proc/locks."""
    held: Dict[int, Set[int]] = {}
    for line in Path('/proc/locks').read_text().splitlines():
        fields = line.split()
        if '->' in fields:  # a waiter, not a holder
            continue
        if len(fields) >= 6 and fields[1] == 'FLOCK':
            held.setdefault(int(fields[4]), set()).add(int(fields[5].rsplit(':', 1)[1]))
    return held


@pytest.mark.slow
def test_killed_process_shared_memory_is_removed(ros_executor: Any,
                                                 ros_processes: Any) -> None:
    from rclpy.node import Node
    from std_msgs.msg import String

    node = Node('shm_probe', context=ros_executor.context)
    ros_executor.add_node(node)
    publisher = node.create_publisher(String, 'shm_probe', 10)
    child = ros_processes.start(
        [sys.executable, str(ECHO_SCRIPT), 'std_msgs/msg/String', 'shm_probe', '1',
         str(CHILD_TIMEOUT)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    assert wait_for(lambda: publisher.get_subscription_count() == 1 or child.poll() is not None,
                    CHILD_TIMEOUT, ros_executor)
    assert child.poll() is None

    # The child's own segments: the Fast DDS lock files it holds an flock on.
    held = _flocks_by_pid()
    inodes_of = {path.stat().st_ino: path for path in SHM_DIR.iterdir()}
    child_locks = {inodes_of[ino] for ino in held.get(child.pid, ()) if ino in inodes_of}
    child_segments = {p for p in child_locks if not p.name.startswith('fastdds_port')}
    ours = {inodes_of[ino] for ino in held.get(os.getpid(), ()) if ino in inodes_of}
    assert child_segments, f'no segment locked by the child in {sorted(inodes_of.values())}'
    assert all(p.name.startswith(('fastdds_', 'fastrtps_')) and p.name.endswith('_el')
               for p in child_segments)
    assert not set(dead_shm_files(min_age=0.0)) & (child_segments | ours)

    os.killpg(child.pid, signal.SIGKILL)
    child.wait(timeout=CHILD_TIMEOUT)
    dead = set(dead_shm_files(min_age=0.0))
    expected = child_segments | {p.with_name(p.name[:-3]) for p in child_segments}
    assert expected <= dead
    assert not dead & ours, 'a segment of this live process was taken for dead'

    removed = set(remove_dead_shm_files(min_age=0.0))
    assert expected <= removed
    assert not any(path.exists() for path in expected)
    assert all(path.exists() for path in ours)
