"""The twin's OPC UA server (asyncua): its tags as variables, writes as commands, ``Step(n)``.

:class:`OpcUaServer` runs an asyncua server in a daemon thread with an event loop of its own.
Every ``update_period`` it takes the tags' values from :meth:`PlcState.refresh
<conveyor_twin.plc.state.PlcState.refresh>` and writes those that changed into the address
space (:mod:`~conveyor_twin.plc.opcua_nodes`), with SourceTimestamp = :data:`EPOCH
<conveyor_twin.plc.opcua_nodes.EPOCH>` + the simulation time of the step (for
``LastRisingTime`` / ``LastFallingTime``: of the edge) and ServerTimestamp = the wall clock.
The twin's step never waits for it: the state's sink only stores references, and the work of
one update is one refresh and at most one write per tag, whatever the clients do (a client
that stalls only fills its own bounded notification queues).

A client's write of ``Belts/<b>/SpeedSetpoint`` or ``Actuators/<a>/Target`` goes through the
:class:`~conveyor_twin.plc.writes.PlcWriter` (validated and queued as a command for the next
step; a rejected write is counted and answered with BadOutOfRange, BadTypeMismatch,
BadNotWritable or BadUserAccessDenied, and nothing is applied). The method
``Twin/Lockstep/Step(n)`` asks the
:class:`~conveyor_twin.plc.lockstep.StepHandshake` for n steps and returns the step index
(outside lockstep: BadInvalidState). Security: :mod:`~conveyor_twin.plc.opcua_security`.

Any exception of the server thread is reported once to the twin's health as
``'OPC UA server'``. No ROS imports.
"""

import asyncio
from concurrent.futures import ThreadPoolExecutor
import datetime
import logging
import threading
from typing import Any, Dict, List, Optional
from urllib.parse import urlparse

from asyncua import Server, ua

from conveyor_twin.health import Health
from conveyor_twin.plc.address import PlcServerError
from conveyor_twin.plc.opcua_nodes import (
    add_step_method, build_twin_nodes, NAMESPACE, sim_datetime, TagNode, TwinAttributeService)
from conveyor_twin.plc.opcua_security import (
    APPLICATION_URI, OpcUaSecurity, server_certificate, TwinUserManager)
from conveyor_twin.plc.writes import WriteRejected

__all__ = ['OpcUaSecurity', 'OpcUaServer', 'HEALTH_NAME', 'STATUS_OF_REASON']

#: What a failure of the server thread is reported as.
HEALTH_NAME = 'OPC UA server'
#: Default period of the variables' updates [s].
UPDATE_PERIOD = 0.02
#: How long :meth:`OpcUaServer.start` waits for the server to listen [s] (a generous bound:
#: loading asyncua's address space takes about a second on an idle machine).
START_TIMEOUT = 120.0
#: How long :meth:`OpcUaServer.stop` waits for the thread to end [s].
STOP_TIMEOUT = 30.0

#: Longest wait between updates done as a plain sleep (stop() waits for it) [s].
_SHORT_WAIT = 0.05

#: The status a client gets for each reason of :class:`WriteRejected`.
STATUS_OF_REASON: Dict[str, int] = {
    'out_of_range': ua.StatusCodes.BadOutOfRange,
    'not_finite': ua.StatusCodes.BadOutOfRange,
    'bad_type': ua.StatusCodes.BadTypeMismatch,
    'not_writable': ua.StatusCodes.BadNotWritable,
    'read_only': ua.StatusCodes.BadUserAccessDenied,
    'not_lockstep': ua.StatusCodes.BadInvalidState,
    'unknown_belt': ua.StatusCodes.BadNodeIdUnknown,
    'unknown_actuator': ua.StatusCodes.BadNodeIdUnknown,
}
_NUMBERS = frozenset((ua.VariantType.Double, ua.VariantType.Float, ua.VariantType.SByte,
                      ua.VariantType.Byte, ua.VariantType.Int16, ua.VariantType.UInt16,
                      ua.VariantType.Int32, ua.VariantType.UInt32, ua.VariantType.Int64,
                      ua.VariantType.UInt64))
_STEP_TYPES = frozenset((ua.VariantType.UInt32, ua.VariantType.UInt16, ua.VariantType.Byte,
                         ua.VariantType.Int32, ua.VariantType.Int64, ua.VariantType.UInt64))

_log = logging.getLogger(__name__)


class OpcUaServer:
    """An OPC UA server of one twin's tags (see the module docstring).

    :param state: the frame sink whose ``refresh()`` gives every tag's value.
    :param writer: validates and queues the clients' writes (sender ``opcua``).
    :param handshake: steps the twin for ``Step(n)``.
    :param host: address to bind (127.0.0.1: this machine only).
    :param port: TCP port; 0 picks a free one (:attr:`port` after :meth:`start`).
    :param health: where a failure of the server thread is reported.
    :param update_period: period of the variables' updates [s], > 0.
    :param security: policy, certificate folder, user and read-only mode.
    :raises ValueError: on a bad ``update_period`` or a ``security.read_only`` that the
        writer does not share.
    """

    def __init__(self, state: Any, writer: Any, handshake: Any, *, host: str, port: int,
                 health: Health, update_period: float = UPDATE_PERIOD,
                 security: Optional[OpcUaSecurity] = None) -> None:
        if not 0.0 < update_period <= 10.0:
            raise ValueError(f'OpcUaServer: update_period {update_period!r} s is outside '
                             '(0, 10] s')
        security = security or OpcUaSecurity()
        if security.read_only and not writer.read_only:
            raise ValueError('OpcUaServer: security.read_only needs a read-only PlcWriter')
        self.state = state
        self.writer = writer
        self.handshake = handshake
        self.host = host
        self.port = port
        self.health = health
        self.update_period = float(update_period)
        self.security = security
        self.tags = tuple(t for t in state.tags if t.opcua)
        #: Counters for diagnostics: updates done, values written, client writes accepted
        #: and rejected, step requests served.
        self.updates = 0
        self.values_written = 0
        self.writes_accepted = 0
        self.writes_rejected = 0
        self.step_requests = 0
        self._thread: Optional[threading.Thread] = None
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._stop: Optional[asyncio.Event] = None
        self._ready = threading.Event()
        self._stopping = threading.Event()
        self._start_error: Optional[BaseException] = None
        self._server: Optional[Server] = None
        self._nodes: List[TagNode] = []
        self._last: List[Any] = []
        self._steps = ThreadPoolExecutor(max_workers=1, thread_name_prefix='opcua_step')

    @property
    def url(self) -> str:
        """The endpoint, ``opc.tcp://HOST:PORT/``."""
        host = f'[{self.host}]' if ':' in self.host else self.host
        return f'opc.tcp://{host}:{self.port}/'

    @property
    def running(self) -> bool:
        """True while the server thread runs."""
        return self._thread is not None and self._thread.is_alive()

    def counters(self) -> Dict[str, float]:
        """The server's counters (``updates``, ``values_written``, ``writes_accepted``,
        ``writes_rejected``, ``step_requests``)."""
        return {'updates': self.updates, 'values_written': self.values_written,
                'writes_accepted': self.writes_accepted,
                'writes_rejected': self.writes_rejected, 'step_requests': self.step_requests}

    def start(self) -> None:
        """Start the server thread and return once the server listens.

        :raises PlcServerError: naming host:port if the server cannot listen there (nothing
            is left running).
        """
        if self._thread is not None:
            raise RuntimeError('OpcUaServer.start: already started')
        self._thread = threading.Thread(target=self._run, name='opcua_server', daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT):
            self.stop()
            raise PlcServerError(f'OPC UA server at {self.host}:{self.port}: not listening '
                                 f'after {START_TIMEOUT:g} s')
        if self._start_error is not None:
            self._thread.join(STOP_TIMEOUT)
            self._thread = None
            self._steps.shutdown(wait=False)
            error = self._start_error
            raise PlcServerError(f'OPC UA server: cannot start at {self.host}:{self.port}: '
                                 f'{error!r}') from error

    def stop(self) -> None:
        """Stop the server and wait for its thread (idempotent; also while it starts)."""
        self._stopping.set()
        loop, stop, thread = self._loop, self._stop, self._thread
        if loop is not None and stop is not None and thread is not None and thread.is_alive():
            try:
                loop.call_soon_threadsafe(stop.set)
            except RuntimeError:  # the loop has closed already
                pass
        if thread is not None and thread is not threading.current_thread():
            thread.join(STOP_TIMEOUT)
            if thread.is_alive():
                self.health.report(HEALTH_NAME, message=f'server thread still running '
                                   f'{STOP_TIMEOUT:g} s after stop ({self.url})')
        self._steps.shutdown(wait=False)

    # --- the server thread -----------------------------------------------------------------

    def _run(self) -> None:
        """The server thread: its own event loop until :meth:`stop` or a failure."""
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())
        except BaseException as exc:  # reported once (or raised by start), never silent
            if self._ready.is_set():
                self.health.report(HEALTH_NAME, exc)
            else:
                self._start_error = exc
        finally:
            try:
                _cancel_tasks(loop)
                loop.run_until_complete(loop.shutdown_asyncgens())
            finally:
                loop.close()
                self._ready.set()

    async def _main(self) -> None:
        self._stop = asyncio.Event()
        server = await self._make_server()
        await server.start()
        try:
            self._fix_port(server)
            self._ready.set()
            if not self._stopping.is_set():  # stop() during the start ends it here
                await self._update_loop()
        finally:
            self._server = None
            await server.stop()

    async def _make_server(self) -> Server:
        """Build and initialise the asyncua server: security, users, the twin's nodes."""
        security = self.security
        server = Server(user_manager=TwinUserManager(security))
        self._server = server
        await server.init()
        server.set_server_name('conveyor_twin')
        await server.set_application_uri(APPLICATION_URI)
        server.set_endpoint(self.url)
        if security.encrypted:
            cert, key = await asyncio.get_running_loop().run_in_executor(
                None, server_certificate, security.cert_dir, self.host)
            await server.load_certificate(str(cert))
            await server.load_private_key(str(key))
            server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
        else:
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        server.set_identity_tokens([ua.UserNameIdentityToken] if security.user
                                   else [ua.AnonymousIdentityToken])
        index = await server.register_namespace(NAMESPACE)
        _, self._nodes = await build_twin_nodes(server, index, self.tags,
                                                   read_only=security.read_only)
        await add_step_method(server, index, self._step)
        iserver = server.iserver
        iserver.attribute_service = TwinAttributeService(iserver.aspace, self._nodes,
                                                         self._client_write)
        self._last = [object()] * len(self._nodes)
        await self._update()
        return server

    def _fix_port(self, server: Server) -> None:
        """With port 0: take the port the system picked and put it into the endpoints."""
        bound = server.bserver.port if server.bserver is not None else self.port
        if bound == self.port:
            return
        old = self.url
        self.port = int(bound)
        server.endpoint = urlparse(self.url)
        for endpoint in server.iserver.endpoints:
            endpoint.EndpointUrl = endpoint.EndpointUrl.replace(old, self.url)
            endpoint.Server.DiscoveryUrls = [u.replace(old, self.url)
                                             for u in endpoint.Server.DiscoveryUrls]

    async def _update_loop(self) -> None:
        """Update the variables every ``update_period`` until stopped (late updates are
        skipped, never caught up)."""
        loop = asyncio.get_running_loop()
        period = self.update_period
        stop = self._stop
        next_time = loop.time()
        while not self._stopping.is_set():
            await self._update()
            next_time += period
            delay = next_time - loop.time()
            if delay < 0.0:
                next_time = loop.time()
                delay = 0.0
            if delay <= _SHORT_WAIT:  # a plain sleep: no task per update
                await asyncio.sleep(delay)
                continue
            try:  # a long period: stop() wakes it
                await asyncio.wait_for(stop.wait(), delay)
            except asyncio.TimeoutError:
                pass

    async def _update(self) -> None:
        """Write every changed value of the state's latest view into the address space."""
        server = self._server
        if server is None:  # stopped while a step request ran
            return
        view = self.state.refresh()
        now = datetime.datetime.now(datetime.timezone.utc)
        stamp = sim_datetime(view.time_ns)
        last = self._last
        written = 0
        for i, node in enumerate(self._nodes):
            value = view.value(node.tag)
            old = last[i]
            if value == old or (value != value and old != old):  # unchanged (NaN too)
                continue
            last[i] = value
            source = sim_datetime(view.edge_ns(node.tag) or 0) if node.edge else stamp
            await server.write_attribute_value(node.nodeid, ua.DataValue(
                ua.Variant(value, node.vtype), SourceTimestamp=source, ServerTimestamp=now))
            written += 1
        self.values_written += written
        self.updates += 1

    # --- requests of clients (on the server's event loop) ---------------------------------

    def _client_write(self, node: TagNode, data: ua.DataValue) -> ua.StatusCode:
        """Validate and queue a client's write of ``node``; return the status it gets.

        A scalar of any numeric variant type is taken as its number (a PLC writing an Int16 0
        means 0.0 m/s); anything else goes to the writer as it is, which refuses it as
        ``bad_type`` (counted)."""
        variant = data.Value
        if variant is None or variant.VariantType == ua.VariantType.Null:
            value: Any = None
        elif variant.VariantType in _NUMBERS and not variant.is_array:
            value = variant.Value
        else:  # refused by the writer as bad_type (counted)
            value = variant.Value if not variant.is_array else list(variant.Value)
        try:
            self.writer.write(node.tag, value)
        except WriteRejected as exc:
            self.writes_rejected += 1
            return ua.StatusCode(STATUS_OF_REASON.get(exc.reason,
                                                      ua.StatusCodes.BadInvalidArgument))
        self.writes_accepted += 1
        return ua.StatusCode()

    async def _step(self, parent: ua.NodeId, *args: ua.Variant) -> ua.CallMethodResult:
        """``Step(n)``: ask the handshake for n steps (in a worker thread, so the variables
        keep updating); return the step index, or a Bad status with the reason."""
        result = ua.CallMethodResult()
        if len(args) != 1:
            return _refused(result, ua.StatusCodes.BadArgumentsMissing if not args
                            else ua.StatusCodes.BadTooManyArguments,
                            f'Step takes one argument n (UInt32), got {len(args)}')
        if self.security.read_only:
            message = 'Step: the PLC interface is read-only'
            self.writer.book.reject('read_only', message)
            return _refused(result, ua.StatusCodes.BadUserAccessDenied, message)
        n = args[0]
        if n.VariantType not in _STEP_TYPES or n.is_array or isinstance(n.Value, bool):
            result.InputArgumentResults = [ua.StatusCode(ua.StatusCodes.BadTypeMismatch)]
            return _refused(result, ua.StatusCodes.BadInvalidArgument,
                            f'Step: n {n.Value!r} of type {n.VariantType.name} is not a UInt32')
        self.step_requests += 1
        loop = asyncio.get_running_loop()
        try:
            index = await loop.run_in_executor(self._steps, self.handshake.request,
                                               int(n.Value))
        except WriteRejected as exc:
            status = STATUS_OF_REASON.get(exc.reason, ua.StatusCodes.BadInvalidArgument)
            if exc.reason == 'out_of_range':
                result.InputArgumentResults = [ua.StatusCode(ua.StatusCodes.BadOutOfRange)]
                status = ua.StatusCodes.BadInvalidArgument
            return _refused(result, status, exc.message)
        except Exception as exc:  # a failed step: the twin's failure, reported
            self.health.report(HEALTH_NAME, exc)
            return _refused(result, ua.StatusCodes.BadInternalError, repr(exc))
        await self._update()  # a read after the call sees the steps
        result.OutputArguments = [ua.Variant(int(index), ua.VariantType.UInt64)]
        return result


def _cancel_tasks(loop: asyncio.AbstractEventLoop) -> None:
    """Cancel and await what is left on ``loop`` (the sessions of clients that never said
    goodbye) so that no task is destroyed pending."""
    pending = [task for task in asyncio.all_tasks(loop) if not task.done()]
    for task in pending:
        task.cancel()
    if pending:
        loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))


def _refused(result: ua.CallMethodResult, status: int, message: str) -> ua.CallMethodResult:
    """Fill ``result`` with a Bad ``status`` and ``message`` (as diagnostic info)."""
    result.StatusCode = ua.StatusCode(status)
    info = ua.DiagnosticInfo()
    info.AdditionalInfo = message
    result.InputArgumentDiagnosticInfos = [info]
    _log.info('OPC UA Step refused: %s', message)
    return result
