"""Attach a twin's PLC servers (OPC UA, Modbus TCP) to its per-step frames and its commands.

:func:`attach_plc` takes a running twin as the composed layout holds it (anything with
``cell``, ``twin``, ``output``, ``runner``, ``health`` and optionally ``counters`` and
``coordinator``: :class:`conveyor_twin.ros.compose.ComposedTwin`) and starts what
:class:`~conveyor_twin.plc.options.PlcOptions` asks for:

- one :class:`~conveyor_twin.plc.state.PlcState`, a sink of the twin's output (O(1) per step;
  the servers' threads decode at their own rate), shared by both servers;
- one :class:`~conveyor_twin.plc.writes.PlcWriter` per server on the twin's command book
  (sender ``opcua`` / ``modbus``): a write is validated and queued like a ``belt_command``,
  recorded, re-simulated, and a rejected one is counted in ``diagnostics``;
- one :class:`~conveyor_twin.plc.lockstep.StepHandshake` on the runner's ``step`` (OPC UA
  ``Step(n)``, the Modbus tick), refused unless the twin is in lockstep and steppable;
- the servers, whose threads report their failure to the twin's ``health``.

:meth:`PlcServers.stop` unsubscribes the state and stops the servers. No ROS imports.
"""

from typing import Any, Callable, Dict, List, Optional

from conveyor_twin.plc.options import PlcOptions

#: ``sender`` of the commands written through each protocol.
OPCUA_SENDER = 'opcua'
MODBUS_SENDER = 'modbus'


class PlcServers:
    """The PLC servers of one twin (either may be None) and what they share.

    :ivar state: the frame sink both servers read.
    :ivar opcua: the OPC UA server, or None.
    :ivar modbus: the Modbus TCP server, or None.
    """

    def __init__(self, state: Any, output: Any) -> None:
        self.state = state
        self._output = output
        self.opcua: Any = None
        self.modbus: Any = None
        self.writers: List[Any] = []
        self._stopped = False
        self._twin: Any = None
        self._rebind: Any = None

    @property
    def opcua_url(self) -> str:
        """The OPC UA endpoint (``opc.tcp://HOST:PORT/``); '' without the server."""
        return self.opcua.url if self.opcua is not None else ''

    @property
    def opcua_port(self) -> int:
        """The port the OPC UA server listens on; 0 without it."""
        return self.opcua.port if self.opcua is not None else 0

    @property
    def modbus_port(self) -> int:
        """The port the Modbus TCP server listens on; 0 without it."""
        return self.modbus.port if self.modbus is not None else 0

    @property
    def modbus_host(self) -> str:
        """The address the Modbus TCP server listens on; '' without it."""
        return getattr(self.modbus, 'host', '') if self.modbus is not None else ''

    def describe(self) -> List[str]:
        """One line per server: where it listens."""
        lines = []
        if self.opcua is not None:
            lines.append(f'OPC UA server at {self.opcua_url}')
        if self.modbus is not None:
            lines.append(f'Modbus TCP server at {self.modbus_host}:{self.modbus_port} '
                         f'(unit id {getattr(self.modbus, "unit_id", 1)})')
        return lines

    def counters(self) -> Dict[str, float]:
        """The servers' counters for ``diagnostics`` and the summary (``plc_...``)."""
        out: Dict[str, float] = {}
        for name, server in (('opcua', self.opcua), ('modbus', self.modbus)):
            if server is None:
                continue
            out[f'plc_{name}_port'] = server.port
            writer = getattr(server, 'writer', None)
            if writer is not None:
                out[f'plc_{name}_writes_accepted'] = writer.accepted
                out[f'plc_{name}_writes_rejected'] = writer.rejected
            counters = getattr(server, 'counters', None)
            if callable(counters):
                out.update({f'plc_{name}_{k}': v for k, v in counters().items()})
        return out

    def follow_resets(self, twin: Any) -> None:
        """After each reset of ``twin`` hand the writers its command book (a reset to another
        cell makes a new one: writes must not go to the old one, which nobody drains)."""
        def rebind() -> None:
            for writer in self.writers:
                writer.book = twin.commands
        self._twin, self._rebind = twin, rebind
        twin.reset_listeners.append(rebind)

    def stop(self) -> None:
        """Stop feeding the state and stop both servers (idempotent)."""
        if self._stopped:
            return
        self._stopped = True
        self._output.unsubscribe(self.state)
        if self._twin is not None and self._rebind in self._twin.reset_listeners:
            self._twin.reset_listeners.remove(self._rebind)
        for server in (self.opcua, self.modbus):
            if server is not None:
                server.stop()


def attach_plc(composed: Any, options: PlcOptions, *, steppable: bool = True,
               mode: Optional[str] = None,
               on_rejected: Optional[Callable[[BaseException], None]] = None) -> PlcServers:
    """Start the PLC servers ``options`` asks for on a running twin; return them.

    :param composed: the twin (see the module docstring for what it must have).
    :param options: addresses, access and security.
    :param steppable: whether a PLC may step the twin (lockstep handshake); False for a
        twin stepped by someone else (a plant's cell), even in lockstep.
    :param mode: the ``Mode`` tag ('realtime', 'fast', 'lockstep'); None: the runner's.
    :param on_rejected: called with each rejected write's error, after it was counted (e.g.
        to log it); None: the coordinator's ``report_rejected`` if ``composed`` has one.
    :raises conveyor_twin.plc.address.PlcServerError: if an address is invalid or a server
        cannot listen there (nothing is left running).
    """
    from conveyor_twin.plc.address import parse_address
    from conveyor_twin.plc.lockstep import StepHandshake
    from conveyor_twin.plc.state import PlcState
    from conveyor_twin.coord.timing import TimeMode

    opcua_address = parse_address(options.opcua, option='opcua') if options.opcua else None
    modbus_address = parse_address(options.modbus, option='modbus') if options.modbus else None
    twin = composed.twin
    runner = composed.runner
    mode_name = mode or runner.mode.value
    handshake = StepHandshake(runner.step,
                              mode_is_lockstep=steppable and runner.mode is TimeMode.LOCKSTEP,
                              index=lambda: twin.step_index)
    state = PlcState(composed.cell, mode=mode_name, counters=getattr(composed, 'counters', None),
                     setpoints=lambda: twin.actuation.belt_target,
                     rejected=lambda: twin.commands.rejected_total, handshake=handshake)
    if on_rejected is None:
        coordinator = getattr(composed, 'coordinator', None)
        on_rejected = getattr(coordinator, 'report_rejected', None)
    servers = PlcServers(state, composed.output)
    servers.follow_resets(twin)
    composed.output.subscribe(state)
    try:
        if opcua_address is not None:
            servers.opcua = _start_opcua(state, _writer(twin, OPCUA_SENDER, options, servers,
                                                        on_rejected),
                                         handshake, opcua_address, options, composed.health)
        if modbus_address is not None:
            servers.modbus = _start_modbus(state, _writer(twin, MODBUS_SENDER, options, servers,
                                                          on_rejected),
                                           handshake, modbus_address, options, composed.health)
    except BaseException:
        servers.stop()
        raise
    return servers


def _writer(twin: Any, sender: str, options: PlcOptions, servers: PlcServers,
            on_rejected: Optional[Callable[[BaseException], None]]) -> Any:
    from conveyor_twin.plc.writes import PlcWriter, WriteRejected
    writer = PlcWriter(twin.commands, sender=sender, read_only=options.read_only)
    if on_rejected is not None:
        write = writer.write

        def logged_write(tag: Any, value: object, **kwargs: Any) -> Any:
            try:
                return write(tag, value, **kwargs)
            except WriteRejected as exc:  # counted by the writer: told, then raised
                on_rejected(exc)
                raise
        writer.write = logged_write
    servers.writers.append(writer)
    return writer


def _start_opcua(state: Any, writer: Any, handshake: Any, address: Any, options: PlcOptions,
                 health: Any) -> Any:
    from conveyor_twin.plc.opcua_security import OpcUaSecurity
    from conveyor_twin.plc.opcua_server import OpcUaServer
    host, port = address
    security = OpcUaSecurity(policy=options.security,
                             cert_dir=options.cert_dir,
                             user=options.user, password=options.password,
                             read_only=options.read_only)
    server = OpcUaServer(state, writer, handshake, host=host, port=port, health=health,
                         security=security)
    server.start()
    return server


def _start_modbus(state: Any, writer: Any, handshake: Any, address: Any, options: PlcOptions,
                  health: Any) -> Any:
    from conveyor_twin.plc.modbus_server import ModbusServer
    host, port = address
    server = ModbusServer(state, writer, handshake, host=host, port=port, health=health,
                          read_only=options.read_only)
    server.start()
    return server
