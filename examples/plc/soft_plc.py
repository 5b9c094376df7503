#!/usr/bin/env python3
"""A soft PLC for the twin: stop the belt when a light barrier is blocked, restart it later.

The program is the one of ``examples/stop_on_barrier.py``, written as a PLC runs it: a cyclic
scan (every 10 ms) that reads its inputs, runs its logic and writes its outputs, here over
OPC UA (an asyncua client) or Modbus TCP (a pymodbus client) instead of ROS 2:

- input: the barrier's ``RisingEdges`` counter (a counter, not the ``Blocked`` bit, so a part
  that passes the beam between two scans is not missed) and ``SimulationTime``;
- output: the belt's ``SpeedSetpoint`` (0 on a new rising edge; ``--run-speed`` again once
  ``--pause`` seconds of simulation time have passed).

Start the twin with its servers, then the PLC::

    conveyor-twin run --duration 0 --opcua 4840 --modbus 5020          # terminal 1
    python examples/plc/soft_plc.py opcua --url opc.tcp://127.0.0.1:4840/
    python examples/plc/soft_plc.py modbus --port 5020

``--lockstep`` (twin started with ``--mode lockstep``): after each scan the PLC steps the
twin by one scan (OPC UA method ``Lockstep/Step``, Modbus ``Lockstep/Tick``), so the run is
the same however fast the PLC and the twin are. The addresses come from the cell's tag map (as
``conveyor-twin plc-map`` prints it); a PLC program would hold them as constants. At the end
the PLC prints one JSON line: scans, stops, restarts, the last simulation time.
"""

import argparse
import asyncio
import json
from pathlib import Path
import sys
import tempfile
import time
from typing import Dict, Optional

from conveyor_twin.cell import load_cell
from conveyor_twin.plc.tags import modbus_value, modbus_words, tag_map

UINT32 = 2 ** 32
NAMESPACE = 'urn:conveyor-twin:twin'


class StopOnBarrier:
    """The PLC program: one call of :meth:`scan` per cycle.

    :param pause: simulation time the belt stays stopped [s].
    :param run_speed: the belt's speed when it runs [m/s].
    """

    def __init__(self, pause: float, run_speed: float) -> None:
        self.pause = pause
        self.run_speed = run_speed
        self.last_edges: Optional[int] = None
        self.stopped_at: Optional[float] = None
        self.stops = 0
        self.restarts = 0
        self.scans = 0
        self.sim_time = 0.0

    def scan(self, rising_edges: int, sim_time: float) -> Optional[float]:
        """Take the inputs of one cycle; return the new setpoint [m/s], or None to keep it."""
        self.scans += 1
        self.sim_time = sim_time
        new_edge = self.last_edges is not None and (rising_edges - self.last_edges) % UINT32
        self.last_edges = rising_edges
        if self.stopped_at is None and new_edge:
            self.stopped_at = sim_time
            self.stops += 1
            return 0.0
        if self.stopped_at is not None and sim_time - self.stopped_at >= self.pause:
            self.stopped_at = None
            self.restarts += 1
            return self.run_speed
        return None

    def result(self) -> Dict[str, object]:
        """What the PLC did."""
        return {'scans': self.scans, 'stops': self.stops, 'restarts': self.restarts,
                'sim_time': self.sim_time}


def _done(args: argparse.Namespace, program: StopOnBarrier, started: float) -> bool:
    if args.sim_duration and program.sim_time >= args.sim_duration:
        return True
    return bool(args.duration) and time.monotonic() - started >= args.duration


async def _sleep_to_next_scan(next_scan: float, period: float) -> float:
    delay = next_scan - time.monotonic()
    if delay > 0:
        await asyncio.sleep(delay)
    return max(next_scan + period, time.monotonic())


async def run_opcua(args: argparse.Namespace, program: StopOnBarrier) -> None:
    """Scan over OPC UA until done."""
    from asyncua import Client, ua
    client = Client(args.url, timeout=10)
    if args.security == 'Basic256Sha256':
        from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
        cert, key = await _client_certificate(Path(args.cert_dir), client)
        await client.set_security(SecurityPolicyBasic256Sha256, certificate=str(cert),
                                  private_key=str(key),
                                  mode=ua.MessageSecurityMode.SignAndEncrypt)
    if args.user:
        client.set_user(args.user)
        client.set_password(args.password)
    async with client:
        ns = await client.get_namespace_index(NAMESPACE)

        def node(path: str):
            return client.get_node(ua.NodeId(f'Twin/{path}', ns))

        edges = node(f'Barriers/{args.barrier}/RisingEdges')
        sim_time = node('SimulationTime')
        setpoint = node(f'Belts/{args.belt}/SpeedSetpoint')
        lockstep, step = node('Lockstep'), node('Lockstep/Step')
        steps = ua.Variant(args.scan_steps, ua.VariantType.UInt32)
        started = next_scan = time.monotonic()
        while not _done(args, program, started):
            count, now = await client.read_values([edges, sim_time])
            out = program.scan(int(count), float(now))
            if out is not None:
                await setpoint.write_value(ua.DataValue(ua.Variant(out, ua.VariantType.Double)))
            if args.lockstep:
                await lockstep.call_method(step, steps)
            else:
                next_scan = await _sleep_to_next_scan(next_scan, args.scan)


async def _client_certificate(folder: Path, client) -> tuple:
    """Return this PLC's certificate and key (made once in ``folder``)."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID
    folder.mkdir(parents=True, exist_ok=True)
    cert, key = folder / 'soft_plc_cert.der', folder / 'soft_plc_key.pem'
    uri = 'urn:conveyor-twin:soft-plc'
    client.application_uri = uri
    await setup_self_signed_certificate(key, cert, uri, 'localhost',
                                        [ExtendedKeyUsageOID.CLIENT_AUTH],
                                        {'commonName': 'conveyor_twin soft PLC'})
    return cert, key


def run_modbus(args: argparse.Namespace, program: StopOnBarrier) -> None:
    """Scan over Modbus TCP until done."""
    from pymodbus.client import ModbusTcpClient
    tags = tag_map(load_cell(args.cell or None))
    edges = tags.by_path(f'Barriers/{args.barrier}/RisingEdges')
    sim_time = tags.by_path('SimulationTime')
    setpoint = tags.by_path(f'Belts/{args.belt}/SpeedSetpoint')
    tick, done_tick = tags.by_path('Lockstep/Tick'), tags.by_path('Lockstep/DoneTick')
    client = ModbusTcpClient(args.host, port=args.port, timeout=10)
    if not client.connect():
        raise SystemExit(f'soft PLC: no Modbus server at {args.host}:{args.port}')

    def read(tag) -> float:
        reply = client.read_input_registers(tag.modbus_address, count=tag.modbus_words,
                                            device_id=args.unit)
        if reply.isError():
            raise RuntimeError(f'soft PLC: reading {tag.path}: {reply}')
        return modbus_value(tag, reply.registers)

    def write(tag, value) -> None:
        reply = client.write_registers(tag.modbus_address, list(modbus_words(tag, value)),
                                       device_id=args.unit)
        if reply.isError():
            raise RuntimeError(f'soft PLC: writing {value!r} to {tag.path}: {reply}')

    ticks = 0
    try:
        started = next_scan = time.monotonic()
        while not _done(args, program, started):
            out = program.scan(int(read(edges)), read(sim_time) / 1000.0)  # ms -> s
            if out is not None:
                write(setpoint, out)
            if args.lockstep:
                ticks = (ticks + 1) % 65536
                write(tick, ticks)
                while int(read(done_tick)) != ticks:  # DoneTick follows once the steps are done
                    time.sleep(0.001)
            else:
                delay = next_scan - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                next_scan = max(next_scan + args.scan, time.monotonic())
    finally:
        client.close()


def build_parser() -> argparse.ArgumentParser:
    """Return the soft PLC's argument parser."""
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('protocol', choices=['opcua', 'modbus'])
    p.add_argument('--url', default='opc.tcp://127.0.0.1:4840/', help='OPC UA endpoint')
    p.add_argument('--security', default='Basic256Sha256', choices=['Basic256Sha256', 'None'],
                   help='OPC UA security policy (as the twin serves it)')
    p.add_argument('--cert-dir', default=str(Path(tempfile.gettempdir()) / 'soft_plc'),
                   help="folder of this PLC's OPC UA client certificate (made once)")
    p.add_argument('--user', default='', help='OPC UA user (the twin\'s --opcua-user)')
    p.add_argument('--password', default='', help='its password')
    p.add_argument('--host', default='127.0.0.1', help='Modbus server host')
    p.add_argument('--port', type=int, default=502, help='Modbus server port')
    p.add_argument('--unit', type=int, default=1, help='Modbus unit (device) id')
    p.add_argument('--cell', default='', help="the twin's cell file (Modbus addresses; "
                   'default: the embedded default cell)')
    p.add_argument('--barrier', default='lb_exit', help='light barrier to watch')
    p.add_argument('--belt', default='main', help='belt to stop and restart')
    p.add_argument('--pause', type=float, default=0.5, help='stop time [s of simulation time]')
    p.add_argument('--run-speed', type=float, default=0.5, help='restart speed [m/s]')
    p.add_argument('--scan', type=float, default=0.01, help='scan period [s]')
    p.add_argument('--lockstep', action='store_true',
                   help='step the twin one scan after each scan (twin in --mode lockstep)')
    p.add_argument('--scan-steps', type=int, default=10,
                   help='--lockstep over OPC UA: steps per scan (Modbus: Lockstep/TickSteps)')
    p.add_argument('--duration', type=float, default=0.0, help='stop after this wall time [s]')
    p.add_argument('--sim-duration', type=float, default=0.0,
                   help='stop once the simulation time reaches this [s]')
    return p


def main(argv=None) -> int:
    """Run the soft PLC; print what it did as one JSON line."""
    args = build_parser().parse_args(argv)
    program = StopOnBarrier(args.pause, args.run_speed)
    try:
        if args.protocol == 'opcua':
            asyncio.run(run_opcua(args, program))
        else:
            run_modbus(args, program)
    except KeyboardInterrupt:
        pass
    print(json.dumps({'protocol': args.protocol, **program.result()}), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
