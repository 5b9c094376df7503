"""Fast DDS shared memory that killed processes leave in ``/dev/shm``, found and removed.

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
import time
from typing import Dict, List, Set

SHM_DIR = Path('/dev/shm')
# A lock file younger than this may belong to a process still setting its segment up [s].
SHM_MIN_AGE = 1.0

_SEGMENT_LOCK = re.compile(r'^(fastdds|fastrtps)_[0-9a-f]{16}_(el|sl)$')
_PORT_LOCK = re.compile(r'^(fastdds|fastrtps)_port(\d{1,5})_(el|sl)$')
_PORT = re.compile(r'^(fastdds|fastrtps)_port\d{1,5}$')
# 01.0f: eProsima's vendor id; then host id (2 octets), pid (low 16 bits, little endian), ...
_DATASHARING = re.compile(
    r'^fast_datasharing_01\.0f\.[0-9a-f]{2}\.[0-9a-f]{2}\.([0-9a-f]{2})\.([0-9a-f]{2})\.')


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
