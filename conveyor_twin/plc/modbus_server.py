"""The twin's Modbus TCP server (pymodbus): its tags as registers, writes as commands.

:class:`ModbusServer` serves the tag map of the cell (:mod:`conveyor_twin.plc.tags`, laid out
by :mod:`conveyor_twin.plc.modbus_registers`) from a pymodbus ``ModbusTcpServer`` running in a
daemon thread with its own asyncio loop. The stepping thread never waits for it: reads are
answered from :meth:`PlcState.refresh <conveyor_twin.plc.state.PlcState.refresh>` (one refresh
serves every read of the next millisecond), writes become commands through the
:class:`~conveyor_twin.plc.writes.PlcWriter`, and a client that stalls or disconnects only
costs its own connection.

Requests and answers:

- function codes 2 (discrete inputs), 4 (input registers) and 3 (holding registers) read; a
  range that touches an address without a tag is answered with exception 02 (Illegal Data
  Address). Reading one register of a 32-bit value is allowed.
- function codes 16 (write multiple registers), 6 (write single register) and 23 write
  holding registers. A write must cover whole values: a float32 setpoint takes both its
  registers in one request (function 16), so a single-register write to half of it is
  answered with exception 03 (Illegal Data Value). A float32 means the shortest decimal it
  shows (:func:`~conveyor_twin.plc.tags.float32_value`: 0.1, not 0.100000001). One request
  may write several values, e.g. the whole holding table each PLC cycle: every value and the
  tick are checked before any is applied (all or nothing), the values are queued before the
  tick steps.
- a value the twin refuses (out of range, NaN or infinite, read-only server) is answered with
  exception 03 and nothing is applied; every refused write is counted in the twin's
  ``RejectedWrites`` (the command book's rejections) and in :meth:`ModbusServer.counters`.
  A write to an address without a writable tag is answered with exception 02, and counted.
- coils: there are none (function codes 1, 5, 15 get exception 02).
- another unit id than the server's is answered with exception 0B (Gateway Target Device
  Failed to Respond), as a gateway would.

Lockstep (:mod:`conveyor_twin.plc.lockstep`): the PLC writes ``Lockstep/Tick`` = last + 1
(mod 65536); the server steps ``Lockstep/TickSteps`` steps (``Lockstep/Done`` is 0 meanwhile)
and answers the write once they are done, with ``Lockstep/DoneTick`` = ``Tick`` and ``Done``
= 1. The same tick again steps nothing (a retried request). Any other tick, or a tick outside
lockstep mode, is answered with exception 03 and counted. Ticks are taken one at a time: a
second client's tick waits for the first.

Failures of the server's thread (or of a request it could not answer) are reported once to
the twin's :class:`~conveyor_twin.health.Health` as ``'Modbus server'``.
"""

import asyncio
import math
import socket
import threading
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.exceptions import NoSuchIdException
from pymodbus.server import ModbusTcpServer

from conveyor_twin.health import Health
from conveyor_twin.plc.address import DEFAULT_HOST, PlcServerError
from conveyor_twin.plc.lockstep import StepHandshake
from conveyor_twin.plc.modbus_registers import ModbusTables, READ_CODES, Table, WRITE_CODES
from conveyor_twin.plc.tags import modbus_value, modbus_words, Tag
from conveyor_twin.plc.writes import PlcWriter, WriteRejected

#: Name under which the server's failures are reported to the twin's health.
MODBUS_SERVER = 'Modbus server'
#: Longest time one :meth:`PlcState.refresh` answers reads for [s].
VIEW_MAX_AGE = 0.001
#: Longest wait for the server to listen, and for its thread to end [s].
START_TIMEOUT = 10.0
STOP_TIMEOUT = 5.0

Answer = Union[List[int], List[bool], ExcCodes]


class ModbusServer:
    """The Modbus TCP server of one twin.

    :param state: the twin's PLC state (a sink of its output); reads come from its refresh.
    :param writer: turns writes into commands (sender ``modbus``).
    :param handshake: the lockstep handshake (``Lockstep/Tick``).
    :param host: address to listen on (127.0.0.1: this machine only).
    :param port: TCP port; 0 picks a free one (then read :attr:`port`).
    :param health: where the server's thread reports its failure.
    :param unit_id: the unit (device) id the server answers to [0, 255].
    :param read_only: refuse every write (exception 03, counted).
    """

    def __init__(self, state: Any, writer: PlcWriter, handshake: StepHandshake, *,
                 host: str = DEFAULT_HOST, port: int = 0, health: Health, unit_id: int = 1,
                 read_only: bool = False) -> None:
        if isinstance(unit_id, bool) or not isinstance(unit_id, int) or not 0 <= unit_id <= 255:
            raise PlcServerError(f'Modbus server: unit id {unit_id!r} is not an integer in '
                                 '[0, 255]')
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise PlcServerError(f'Modbus server: port {port!r} is not an integer in '
                                 '[0, 65535]')
        self.state = state
        self.writer = writer
        self.handshake = handshake
        self.host = host
        self.port = port
        self.health = health
        self.unit_id = unit_id
        self.read_only = read_only
        self.tables = ModbusTables(state.map)
        self._view: Any = None
        self._view_at = -math.inf
        self._lockstep: Dict[str, object] = {}
        self._listening = False
        self._requests = 0
        self._rejected = 0
        self._thread: Optional[threading.Thread] = None
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._stopping: Optional[asyncio.Event] = None
        self._tick_lock: Optional[asyncio.Lock] = None
        self._ready = threading.Event()
        self._start_error: Optional[BaseException] = None

    # --- life cycle -------------------------------------------------------------------------

    def start(self) -> None:
        """Listen at host:port and serve in a daemon thread.

        :raises PlcServerError: naming host:port if it cannot listen there; nothing is left
            running then.
        """
        if self._thread is not None:
            raise PlcServerError(f'Modbus server at {self.host}:{self.port}: already started')
        self._thread = self.health.thread(MODBUS_SERVER, self._run)
        self._thread.name = 'modbus_server'
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT):
            self.stop()
            raise PlcServerError(f'Modbus server at {self.host}:{self.port}: not listening '
                                 f'after {START_TIMEOUT:g} s')
        if self._start_error is not None or not self._listening:
            self._thread.join(STOP_TIMEOUT)
            raise PlcServerError(f'Modbus server: cannot listen at {self.host}:{self.port}: '
                                 f'{self._why(self._start_error)}') from self._start_error

    def stop(self) -> None:
        """Close every connection and the listening socket; end the thread (idempotent)."""
        thread, loop = self._thread, self._loop
        if thread is None or loop is None or not thread.is_alive():
            return
        try:
            loop.call_soon_threadsafe(self._stopping.set)
        except RuntimeError:  # the loop closed meanwhile
            return
        thread.join(STOP_TIMEOUT)
        if thread.is_alive():
            self.health.report(MODBUS_SERVER, message=f'thread did not end within '
                               f'{STOP_TIMEOUT:g} s of stop()')

    @property
    def running(self) -> bool:
        """True while the server's thread serves."""
        return self._listening and self._thread is not None and self._thread.is_alive()

    def counters(self) -> Dict[str, float]:
        """Requests answered and writes refused by this server (for ``diagnostics``)."""
        return {'requests': self._requests, 'rejected': self._rejected}

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        loop.set_exception_handler(self._loop_exception)
        self._stopping = asyncio.Event()
        self._tick_lock = asyncio.Lock()
        self._loop = loop
        try:
            loop.run_until_complete(self._serve())
        finally:
            self._ready.set()  # a start() still waiting learns that it ended
            loop.close()

    async def _serve(self) -> None:
        try:
            context = _Context(self)
            server = ModbusTcpServer(context, address=(self.host, self.port))
            if server.context is not context:  # another pymodbus than 3.16
                raise PlcServerError('this pymodbus does not serve a custom datastore '
                                     '(expected pymodbus 3.16)')
            await server.serve_forever(background=True)
        except Exception as exc:  # raised by start(), in the caller's thread
            self._start_error = exc
            return
        try:
            self.port = server.transport.sockets[0].getsockname()[1]
            self._listening = True
            self._ready.set()
            await self._stopping.wait()
        finally:
            self._listening = False
            await server.shutdown()

    def _why(self, exc: Optional[BaseException]) -> str:
        if exc is None:
            return 'its thread ended (reported as a failure of the Modbus server)'
        if isinstance(exc, RuntimeError):  # pymodbus: "Could not start listen"
            return _bind_error(self.host, self.port)
        return str(exc) or type(exc).__name__

    def _loop_exception(self, loop: asyncio.AbstractEventLoop, context: dict) -> None:
        exc = context.get('exception')
        if exc is None:
            self.health.report(MODBUS_SERVER, message=str(context.get('message', context)))
        elif not isinstance(exc, (ConnectionError, asyncio.CancelledError)):
            self.health.report(MODBUS_SERVER, exc)

    # --- requests (on the server's loop) ----------------------------------------------------

    async def read(self, unit: int, function: int, address: int, count: int) -> Answer:
        """Answer a read of ``count`` bits or registers from ``address`` (function code
        ``function``): the values, or the Modbus exception code."""
        self._check_unit(unit)
        self._requests += 1
        try:
            table = self.tables[READ_CODES[function]]
            if not table.covers(address, count):
                return ExcCodes.ILLEGAL_ADDRESS
            return self._words(table, address, count)
        except Exception as exc:  # reported once; the client gets 04
            self.health.report(MODBUS_SERVER, exc)
            return ExcCodes.DEVICE_FAILURE

    async def write(self, unit: int, function: int, address: int,
                    values: Sequence[int]) -> Optional[ExcCodes]:
        """Take a write of ``values`` from ``address``: None if applied, else the Modbus
        exception code (nothing applied)."""
        self._check_unit(unit)
        self._requests += 1
        try:
            return await self._write(function, address, [int(v) for v in values])
        except Exception as exc:  # reported once; the client gets 04
            self.health.report(MODBUS_SERVER, exc)
            return ExcCodes.DEVICE_FAILURE

    def _check_unit(self, unit: int) -> None:
        if unit != self.unit_id:
            raise NoSuchIdException(f'unit id {unit} (this server answers {self.unit_id})')

    def view(self) -> Tuple[Any, Dict[str, object]]:
        """Return the state's view, refreshed if older than :data:`VIEW_MAX_AGE` or if a tick
        ended since, and the lockstep values it goes with.

        The lockstep values are read before the refresh: a view showing ``DoneTick`` = k
        holds every frame of tick k.
        """
        hs = self.handshake
        lockstep = {'tick': hs.tick, 'tick_steps': hs.tick_steps, 'done_tick': hs.done_tick,
                    'done': hs.done}
        now = time.perf_counter()
        if now - self._view_at > VIEW_MAX_AGE or lockstep != self._lockstep:
            self._view = self.state.refresh()
            self._view_at = now
            self._lockstep = lockstep
        return self._view, self._lockstep

    def _words(self, table: Table, address: int, count: int) -> Union[List[int], List[bool]]:
        view, lockstep = self.view()
        out: List[int] = []
        end = address + count
        while address < end:
            tag, word = table.owners[address]
            value = lockstep[tag.source[1]] if tag.source[0] == 'lockstep' else view.value(tag)
            words = modbus_words(tag, value)
            taken = words[word:word + end - address]
            out.extend(taken)
            address += len(taken)
        if table.name in ('coil', 'discrete'):
            return [bool(bit) for bit in out]
        return out

    async def _write(self, function: int, address: int, values: List[int]) -> Optional[ExcCodes]:
        table = self.tables[WRITE_CODES[function]]
        where = f'Modbus write of {table.name} [{address}, {address + len(values)})'
        if self.read_only:
            return self._refuse('read_only', f'{where}: the PLC interface is read-only',
                                ExcCodes.ILLEGAL_VALUE)
        if table.name != 'holding' or not table.covers(address, len(values)):
            return self._refuse('bad_address', f'{where}: no writable tag at every address '
                                f'(holding registers 0..{self.tables["holding"].size - 1})',
                                ExcCodes.ILLEGAL_ADDRESS)
        tags = table.whole_tags(address, len(values))
        if tags is None:
            return self._refuse('partial_value', f'{where} splits a 32-bit value: write both '
                                'registers of a float32 in one request (function 16)',
                                ExcCodes.ILLEGAL_VALUE)
        items = [(tag, modbus_value(tag, values[tag.modbus_address - address:
                                                tag.modbus_address - address + tag.modbus_words]))
                 for tag in tags]
        commands = [(tag, value) for tag, value in items if tag.source[0] != 'lockstep']
        lockstep = {tag.source[1]: value for tag, value in items if tag.source[0] == 'lockstep'}
        if len(items) > 1 and not self._all_valid(commands, lockstep.get('tick')):
            return ExcCodes.ILLEGAL_VALUE
        hs = self.handshake
        steps_before = hs.tick_steps
        if 'tick_steps' in lockstep and not self._take(hs.set_tick_steps,
                                                       lockstep['tick_steps']):
            return ExcCodes.ILLEGAL_VALUE
        for tag, value in commands:
            try:
                self.writer.write(tag, value)
            except WriteRejected:  # counted by the writer
                self._rejected += 1
                hs.tick_steps = steps_before
                return ExcCodes.ILLEGAL_VALUE
        if 'tick' in lockstep:
            return await self._tick(lockstep['tick'])
        return None

    def _all_valid(self, commands: Sequence[Tuple[Tag, float]], tick: Optional[int]) -> bool:
        """Check every value of a write of several before applying any: the commands by the
        command book's rules, a tick by the handshake's (a refusal is counted)."""
        book = self.writer.book
        for tag, value in commands:
            validate = book.validate_belt if tag.source[0] == 'belt' else book.validate_actuator
            try:
                validate(tag.target, value)
            except ValueError:  # counted by the book
                self._rejected += 1
                return False
        hs = self.handshake
        if tick is None or (hs.mode_is_lockstep and tick in (hs.tick, (hs.tick + 1) % 65536)):
            return True
        if not hs.mode_is_lockstep:
            self._refuse('not_lockstep', f'Lockstep/Tick {tick}: the twin is not in lockstep '
                         'mode', None)
        else:
            self._refuse('out_of_range', f'Lockstep/Tick {tick}: expected '
                         f'{(hs.tick + 1) % 65536} (the last tick + 1) or {hs.tick} again', None)
        return False

    def _take(self, setter: Any, value: int) -> bool:
        try:
            setter(value)
        except WriteRejected as exc:
            self._refuse(exc.reason, exc.message, None)
            return False
        return True

    async def _tick(self, tick: int) -> Optional[ExcCodes]:
        async with self._tick_lock:
            loop = asyncio.get_running_loop()
            try:
                await loop.run_in_executor(None, self.handshake.on_tick, tick)
            except WriteRejected as exc:
                self._refuse(exc.reason, exc.message, None)
                return ExcCodes.ILLEGAL_VALUE
        return None

    def _refuse(self, reason: str, message: str,
                code: Optional[ExcCodes]) -> Optional[ExcCodes]:
        """Count a refused write in the command book (``RejectedWrites``); return ``code``."""
        self.writer.book.reject(reason, message)
        self._rejected += 1
        return code


class _Context(ModbusServerContext):
    """The server's datastore: every read and write goes to the :class:`ModbusServer`.

    pymodbus 3.16 hands requests to a ``ModbusServerContext`` it finds flagged
    ``old_simulator`` as they come (instead of its own register simulator); the base class's
    constructor, which builds that simulator, is not called.
    """

    def __init__(self, server: ModbusServer) -> None:  # pylint: disable=super-init-not-called
        self.old_simulator = True
        self.simdevices = []
        self._server = server

    async def async_getValues(self, device_id: int, func_code: int, address: int,
                              count: int = 1) -> Answer:
        return await self._server.read(device_id, func_code, address, count)

    async def async_setValues(self, device_id: int, func_code: int, address: int,
                              values: Sequence[int]) -> Optional[ExcCodes]:
        return await self._server.write(device_id, func_code, address, values)

    def device_ids(self) -> List[int]:
        return [self._server.unit_id]


def _bind_error(host: str, port: int) -> str:
    """Return why ``host:port`` cannot be bound, as the OS says it (pymodbus only says that
    listening failed)."""
    try:
        family, kind, proto, _, address = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind(address)
    except OSError as exc:
        return exc.strerror or str(exc)
    return 'address in use or not available'
