"""The Fast DDS discovery server of a plant: cells on several hosts without multicast.

ROS 2 processes find each other by multicast (or by ``ROS_STATIC_PEERS``) unless they are
clients of a Fast DDS discovery server: then each process announces itself to the server only,
and learns from it the processes it has topics in common with (the data still flows directly
between the processes). :func:`parse_discovery_server` reads the plant's
``--discovery-server`` option, :func:`client_environment` is the environment of a client (read
by Fast DDS when a process's first participant is created) and :class:`DiscoveryServer` runs
the server (``fast-discovery-server``, shipped with Fast DDS and the ROS 2 wheels) as a child
process, supervised: its end before :meth:`DiscoveryServer.stop` is reported once to a
:class:`~conveyor_twin.health.Health`, with its exit status and its last output.

No ROS imports.
"""

from collections import deque
from dataclasses import dataclass
import functools
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from typing import Deque, Dict, List, Optional, Sequence

from conveyor_twin.health import Health
from conveyor_twin.plant.supervisor import describe_status, end_process

#: The port Fast DDS' discovery server listens on unless told otherwise.
DEFAULT_PORT = 11811
#: Where a server started without a host listens: this machine only.
DEFAULT_HOST = '127.0.0.1'
SERVER_EXECUTABLE = 'fast-discovery-server'
#: Longest wait for a started server to say it runs [s] (a bound for a loaded machine).
READY_TIMEOUT = 60.0
#: Lines of the server's output kept for the report of its end.
TAIL_LINES = 12
#: What the server prints once it listens (Fast DDS 2.x, 3.x).
READY_MARKS = ('Server is running', 'Server started')
#: The environment variables a Fast DDS participant reads when it is created.
ENV_SERVER = 'ROS_DISCOVERY_SERVER'
ENV_SUPER_CLIENT = 'ROS_SUPER_CLIENT'
_START = 'start'
_HOST = re.compile(r'^[A-Za-z0-9]([A-Za-z0-9.-]*[A-Za-z0-9])?$')
_ANSI = re.compile(r'\x1b\[[0-9;]*m')


class DiscoveryError(ValueError):
    """A bad ``--discovery-server`` value, or a discovery server that could not start."""


@dataclass(frozen=True)
class DiscoveryAddress:
    """Where a discovery server listens (UDP).

    :param host: an IPv4 address or a host name (``0.0.0.0``: every interface).
    :param port: UDP port [1, 65535].
    """

    host: str
    port: int

    def __str__(self) -> str:
        return f'{self.host}:{self.port}'

    def for_clients(self) -> 'DiscoveryAddress':
        """The address clients on this host use (``0.0.0.0`` is reached at 127.0.0.1)."""
        return DiscoveryAddress('127.0.0.1', self.port) if self.host == '0.0.0.0' else self


@dataclass(frozen=True)
class DiscoverySetting:
    """What ``--discovery-server`` asks for.

    :param address: the server's address.
    :param start: True: start a server listening there (this process supervises it);
        False: use the server running there.
    """

    address: DiscoveryAddress
    start: bool

    def describe(self) -> str:
        """The option's value as given back to a cell process: ``HOST:PORT`` to use."""
        return str(self.address.for_clients())


def parse_address(text: str, *, option: str = '--discovery-server',
                  given: Optional[str] = None) -> DiscoveryAddress:
    """Read ``[HOST:]PORT`` (HOST defaults to 127.0.0.1).

    :param given: the whole value the option got, for the message (default: ``text``).
    :raises DiscoveryError: naming ``option``, the value and what is allowed.
    """
    given = text if given is None else given
    host, sep, port_text = text.rpartition(':')
    if not sep:
        host = DEFAULT_HOST
    expected = ('expected [HOST:]PORT, HOST an IPv4 address or a host name, PORT an integer '
                'in [1, 65535]')
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise DiscoveryError(f'{option}: got {given!r}; {expected}')
    if not _HOST.match(host):
        raise DiscoveryError(f'{option}: got {given!r} (host {host!r}); {expected}')
    return DiscoveryAddress(host, int(port_text))


def parse_discovery_server(text: str, *, option: str = '--discovery-server') -> DiscoverySetting:
    """Read ``[HOST:]PORT`` (use the server there; HOST defaults to 127.0.0.1) or
    ``start[:[HOST:]PORT]`` (start one listening there; default 127.0.0.1:11811).

    :raises DiscoveryError: naming ``option``, the value and what is allowed.
    """
    if text == _START:
        return DiscoverySetting(DiscoveryAddress(DEFAULT_HOST, DEFAULT_PORT), start=True)
    if text.startswith(_START + ':'):
        return DiscoverySetting(parse_address(text[len(_START) + 1:], option=option,
                                              given=text), start=True)
    if not text:
        raise DiscoveryError(f'{option}: got {text!r}; expected [HOST:]PORT (use the server '
                             'there) or start[:[HOST:]PORT] (start one)')
    return DiscoverySetting(parse_address(text, option=option), start=False)


def client_environment(address: DiscoveryAddress, *,
                       super_client: bool = False) -> Dict[str, str]:
    """Return the environment variables of a client of the server at ``address``.

    A client discovers only through the server (no multicast, no initial peers). A super
    client (``ros2`` command line tools, graph views) learns every process and topic; a plain
    client only those it has topics in common with.
    """
    env = {ENV_SERVER: str(address.for_clients())}
    if super_client:
        env[ENV_SUPER_CLIENT] = 'TRUE'
    return env


def find_server_executable() -> str:
    """Return the path of ``fast-discovery-server``: beside this Python (a virtual environment
    with the ROS 2 wheels), else on ``PATH`` (a sourced ROS 2 install).

    :raises DiscoveryError: when there is none.
    """
    beside = os.path.join(os.path.dirname(sys.executable), SERVER_EXECUTABLE)
    if os.access(beside, os.X_OK):
        return beside
    found = shutil.which(SERVER_EXECUTABLE)
    if found is None:
        raise DiscoveryError(f'no {SERVER_EXECUTABLE} in {os.path.dirname(sys.executable)} or '
                             'on PATH: it comes with Fast DDS (the ROS 2 wheels, or a ROS 2 '
                             'install with its setup file sourced)')
    return found


@functools.lru_cache(maxsize=None)
def _needs_command_index(executable: str) -> bool:
    """True for the tool of Fast DDS 3 (ROS 2 Kilted), which takes a command index first (42:
    run a server) and refuses ``-h`` without one."""
    try:
        probe = subprocess.run([executable, '-h'], capture_output=True, text=True,
                               errors='replace', timeout=READY_TIMEOUT)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return 'fastdds discovery' in probe.stdout + probe.stderr


def server_command(listen: DiscoveryAddress, executable: Optional[str] = None) -> List[str]:
    """Return the command line of a server (id 0) listening at ``listen``."""
    exe = executable or find_server_executable()
    index = ['42'] if _needs_command_index(exe) else []
    return [exe, *index, '-i', '0', '-l', listen.host, '-p', str(listen.port)]


class DiscoveryServer:
    """A Fast DDS discovery server in a child process, supervised.

    :param listen: where it listens.
    :param health: where its end before :meth:`stop` is reported (as ``'discovery server'``).
    :param command: its command line (default: :func:`server_command`).
    """

    NAME = 'discovery server'

    def __init__(self, listen: DiscoveryAddress, *, health: Health,
                 command: Optional[Sequence[str]] = None) -> None:
        self.listen = listen
        self.health = health
        self._command = list(command) if command is not None else None
        self.tail: Deque[str] = deque(maxlen=TAIL_LINES)
        self.popen: Optional[subprocess.Popen] = None
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._ended = threading.Event()
        self._stopping = False
        self._reader: Optional[threading.Thread] = None

    @property
    def pid(self) -> Optional[int]:
        """The server's process id (None before :meth:`start`)."""
        return self.popen.pid if self.popen is not None else None

    def alive(self) -> bool:
        """True while the server's process runs."""
        return self.popen is not None and self.popen.poll() is None

    def start(self, timeout: float = READY_TIMEOUT) -> None:
        """Start the server and wait until it listens.

        :param timeout: longest wait for it to say it runs [s].
        :raises DiscoveryError: it ended first (its port taken, a bad address) or did not
            say it runs in time (it is then stopped).
        """
        command = self._command or server_command(self.listen)
        try:
            self.popen = subprocess.Popen(command, stdin=subprocess.DEVNULL,
                                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                          text=True, errors='replace', start_new_session=True)
        except OSError as exc:
            raise DiscoveryError(f'{self.NAME} on {self.listen}: {command[0]}: {exc}') from None
        self._reader = self.health.thread(f'{self.NAME} output reader', self._read,
                                          self.popen.stdout)
        self._reader.start()
        deadline = time.monotonic() + timeout
        while not self._ready.wait(0.05):
            if self._ended.is_set() or time.monotonic() > deadline:
                break
        if not self._ready.is_set():
            code = self.stop(5.0)
            raise DiscoveryError(f'{self.NAME} on {self.listen} did not start (exit status '
                                 f'{describe_status(code) if code is not None else "none"}): '
                                 f'{self.last_line()}')

    def _read(self, stream) -> None:
        for raw in stream:
            line = _ANSI.sub('', raw.rstrip('\n'))
            with self._lock:
                self.tail.append(line)
            if any(mark in line for mark in READY_MARKS):
                self._ready.set()
        code = self.popen.wait()
        self._ended.set()
        if not self._stopping and self._ready.is_set():
            self.health.report(self.NAME, message=f'{self.listen}: exit status '
                               f'{describe_status(code)}; last output: {self.last_line()}',
                               detail='\n'.join(self.last_lines()))

    def last_lines(self) -> List[str]:
        """The last lines of the server's output."""
        with self._lock:
            return list(self.tail)

    def last_line(self) -> str:
        """The last non-empty line of the server's output, or ``(no output)``."""
        lines = [x for x in self.last_lines() if x.strip()]
        return lines[-1].strip() if lines else '(no output)'

    def stop(self, timeout: float = 5.0) -> Optional[int]:
        """Stop the server (SIGINT, SIGKILL to its group after ``timeout`` [s]); not a failure.

        :return: its exit status (None if it was never started).
        """
        if self.popen is None:
            return None
        self._stopping = True
        return end_process(self.popen, self._reader, timeout)
