"""Real OPC UA and Modbus TCP clients of a twin's PLC servers, as a PLC would poll them."""

from typing import Dict, List, Sequence

from conveyor_twin.plc.tags import modbus_value, modbus_words, Tag, TagMap

NAMESPACE = 'urn:conveyor-twin:twin'


class OpcUa:
    """A synchronous asyncua client (security None unless told) reading tags by path."""

    def __init__(self, url: str, *, timeout: float = 30.0) -> None:
        from asyncua.sync import Client
        self.client = Client(url, timeout=timeout)
        self.client.connect()
        self.ns = self.client.get_namespace_index(NAMESPACE)

    def node(self, path: str):
        from asyncua import ua
        return self.client.get_node(ua.NodeId(f'Twin/{path}', self.ns))

    def read(self, paths: Sequence[str]) -> List[object]:
        """Read the values of ``paths`` in one request."""
        return self.client.read_values([self.node(p) for p in paths])

    def write_double(self, path: str, value: float) -> None:
        """Write a Double (raises the server's Bad status as an exception)."""
        from asyncua import ua
        self.node(path).write_value(ua.DataValue(ua.Variant(value, ua.VariantType.Double)))

    def step(self, n: int) -> int:
        """Call ``Lockstep/Step(n)``; return the step index it answers."""
        from asyncua import ua
        return int(self.node('Lockstep').call_method(self.node('Lockstep/Step'),
                                                     ua.Variant(n, ua.VariantType.UInt32)))

    def close(self) -> None:
        self.client.disconnect()


class Modbus:
    """A pymodbus TCP client reading whole tables and decoding tags."""

    def __init__(self, port: int, tags: TagMap, *, host: str = '127.0.0.1') -> None:
        from pymodbus.client import ModbusTcpClient
        self.tags = tags
        self.client = ModbusTcpClient(host, port=port, timeout=30)
        assert self.client.connect(), f'no Modbus server at {host}:{port}'

    def inputs(self) -> Dict[str, object]:
        """Read every input register and discrete input; return {path: value}."""
        out: Dict[str, object] = {}
        regs = self._read('input', self.client.read_input_registers, 'registers')
        bits = self._read('discrete', self.client.read_discrete_inputs, 'bits')
        for tag in self.tags.modbus('input'):
            a = tag.modbus_address
            out[tag.path] = modbus_value(tag, regs[a:a + tag.modbus_words])
        for tag in self.tags.modbus('discrete'):
            out[tag.path] = bool(bits[tag.modbus_address])
        return out

    def _read(self, table: str, call, field: str) -> list:
        size = self.tags.modbus_size(table)
        values: list = []
        for start in range(0, size, 120):
            count = min(120, size - start)
            reply = call(start, count=count)
            assert not reply.isError(), f'{table} {start}+{count}: {reply}'
            values += list(getattr(reply, field))[:count]
        return values

    def write(self, tag: Tag, value: float):
        """Write ``value`` to a holding tag (FC16); return the reply (check ``isError()``)."""
        return self.client.write_registers(tag.modbus_address, list(modbus_words(tag, value)))

    def close(self) -> None:
        self.client.close()
