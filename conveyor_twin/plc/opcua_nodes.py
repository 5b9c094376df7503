"""The twin's OPC UA address space: the ``Twin`` object, its variables, and client writes.

Below ``Objects`` the server shows one object ``Twin`` (namespace :data:`NAMESPACE`) with a
variable per OPC UA tag of the cell's tag map (:func:`conveyor_twin.plc.tags.tag_map`), in
folders along the tag's path (``Twin/Barriers/lb_entry/Blocked``; the node id is the string
``Twin/`` + path), and the method ``Twin/Lockstep/Step(n)``. Writes of clients to these
variables do not reach the address space: :class:`TwinAttributeService` hands them to the
server, which validates and queues them as commands; the variables show what the twin does,
not what was written.

No ROS imports.
"""

from dataclasses import dataclass
import datetime
from typing import Awaitable, Callable, Dict, List, Sequence, Tuple

from asyncua import Node, Server, ua
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.server.address_space import AddressSpace, AttributeService

from conveyor_twin.plc.tags import Tag, TagKind

#: Namespace URI of the twin's nodes.
NAMESPACE = 'urn:conveyor-twin:twin'
#: Browse name (and node id) of the twin object below ``Objects``.
TWIN_OBJECT = 'Twin'
#: The folder (below the twin object) of the lockstep handshake: ``Done`` and ``Step(n)``.
LOCKSTEP = 'Lockstep'
#: Zero of simulation time in timestamps (a SourceTimestamp is this + simulation time).
EPOCH = datetime.datetime(1970, 1, 1, tzinfo=datetime.timezone.utc)

#: The OPC UA variant type of each tag kind.
VARIANT_TYPES: Dict[TagKind, ua.VariantType] = {
    TagKind.BOOL: ua.VariantType.Boolean, TagKind.UINT32: ua.VariantType.UInt32,
    TagKind.UINT64: ua.VariantType.UInt64, TagKind.FLOAT64: ua.VariantType.Double,
    TagKind.STRING: ua.VariantType.String}
_INITIAL = {TagKind.BOOL: False, TagKind.UINT32: 0, TagKind.UINT64: 0,
            TagKind.FLOAT64: 0.0, TagKind.STRING: ''}
_READ = ua.AccessLevel.CurrentRead.mask
_READ_WRITE = ua.AccessLevel.CurrentRead.mask | ua.AccessLevel.CurrentWrite.mask


@dataclass(frozen=True)
class TagNode:
    """One tag's variable.

    :param tag: the tag.
    :param nodeid: its node.
    :param vtype: its variant type.
    :param edge: its SourceTimestamp is the time of the last edge it shows
        (``LastRisingTime``, ``LastFallingTime``), not that of the latest step.
    """

    tag: Tag
    nodeid: ua.NodeId
    vtype: ua.VariantType
    edge: bool


def sim_datetime(time_ns: int) -> datetime.datetime:
    """Return the timestamp of simulation time ``time_ns`` [ns]: :data:`EPOCH` + that time
    (microsecond resolution, truncated)."""
    return EPOCH + datetime.timedelta(microseconds=time_ns // 1000)


def is_edge_time(tag: Tag) -> bool:
    """True if ``tag`` shows the time of a light barrier's last edge."""
    return tag.source[0] == 'barrier' and tag.source[-1] in ('last_rising', 'last_falling')


async def build_twin_nodes(server: Server, index: int, tags: Sequence[Tag], *,
                           read_only: bool) -> Tuple[Node, List[TagNode]]:
    """Add the twin object and one variable per tag (OPC UA tags only) below ``Objects``.

    :param index: the namespace index of :data:`NAMESPACE`.
    :param read_only: show the writable tags as not writable for clients (UserAccessLevel).
    :return: the twin object and the variables in tag order.
    """
    twin = await server.nodes.objects.add_object(ua.NodeId(TWIN_OBJECT, index),
                                                 ua.QualifiedName(TWIN_OBJECT, index))
    folders: Dict[str, Node] = {'': twin}
    await _folder(folders, LOCKSTEP, index)  # holds Step(n) whatever the tags
    out: List[TagNode] = []
    for tag in tags:
        if not tag.opcua:
            continue
        folder, _, name = tag.path.rpartition('/')
        parent = await _folder(folders, folder, index)
        vtype = VARIANT_TYPES[tag.kind]
        nodeid = ua.NodeId(f'{TWIN_OBJECT}/{tag.path}', index)
        var = await parent.add_variable(nodeid, ua.QualifiedName(name, index),
                                        _INITIAL[tag.kind], varianttype=vtype)
        unit = f' [{tag.unit}]' if tag.unit else ''
        await var.write_attribute(ua.AttributeIds.Description, ua.DataValue(
            ua.Variant(ua.LocalizedText(tag.description + unit), ua.VariantType.LocalizedText)))
        if tag.writable:
            await var.write_attribute(ua.AttributeIds.AccessLevel, ua.DataValue(
                ua.Variant(_READ_WRITE, ua.VariantType.Byte)))
            await var.write_attribute(ua.AttributeIds.UserAccessLevel, ua.DataValue(
                ua.Variant(_READ if read_only else _READ_WRITE, ua.VariantType.Byte)))
        out.append(TagNode(tag, nodeid, vtype, is_edge_time(tag)))
    return twin, out


async def _folder(folders: Dict[str, Node], path: str, index: int) -> Node:
    """Return the folder object at ``path`` below the twin, creating it and its parents."""
    if path in folders:
        return folders[path]
    parent_path, _, name = path.rpartition('/')
    parent = await _folder(folders, parent_path, index)
    node = await parent.add_folder(ua.NodeId(f'{TWIN_OBJECT}/{path}', index),
                                   ua.QualifiedName(name, index))
    folders[path] = node
    return node


#: Handles a client's write of one tag variable's value; returns the write's status.
WriteHandler = Callable[[TagNode, ua.DataValue], ua.StatusCode]


class TwinAttributeService(AttributeService):
    """asyncua's attribute service with the writes to the twin's variables intercepted.

    A write of a tag variable's Value goes to ``handler`` (validated and queued as a command,
    or refused with its status code), never into the address space; any other attribute of
    these variables is not writable (BadNotWritable). Writes to other nodes are served as
    asyncua serves them.
    """

    def __init__(self, aspace: AddressSpace, nodes: Sequence[TagNode],
                 handler: WriteHandler) -> None:
        super().__init__(aspace)
        self._nodes = {node.nodeid: node for node in nodes}
        self._handler = handler

    async def write(self, params: ua.WriteParameters,
                    user: User = User(role=UserRole.Admin)) -> List[ua.StatusCode]:
        """Answer each write of ``params`` with its status, in order."""
        results: List[ua.StatusCode] = []
        others: List[int] = []
        for i, item in enumerate(params.NodesToWrite):
            node = self._nodes.get(item.NodeId)
            if node is None:
                others.append(i)
                results.append(ua.StatusCode())
            elif item.AttributeId != ua.AttributeIds.Value or item.IndexRange:
                results.append(ua.StatusCode(ua.StatusCodes.BadNotWritable))
            else:
                results.append(self._handler(node, item.Value))
        if others:
            rest = ua.WriteParameters()
            rest.NodesToWrite = [params.NodesToWrite[i] for i in others]
            for i, status in zip(others, await super().write(rest, user)):
                results[i] = status
        return results


async def add_step_method(server: Server, index: int,
                          call: Callable[..., Awaitable[ua.CallMethodResult]]) -> Node:
    """Add the method ``Step(n: UInt32) -> UInt64`` (steps n, returns the step index) to the
    object ``Twin/Lockstep`` (beside ``Done``; the twin object's ``Step`` is the step index
    variable); ``call(parent, n_variant)`` serves it."""
    lockstep = server.get_node(ua.NodeId(f'{TWIN_OBJECT}/{LOCKSTEP}', index))
    n = ua.Argument()
    n.Name = 'n'
    n.DataType = ua.NodeId(ua.ObjectIds.UInt32)
    n.ValueRank = -1
    n.Description = ua.LocalizedText('steps to advance [1]')
    step = ua.Argument()
    step.Name = 'step'
    step.DataType = ua.NodeId(ua.ObjectIds.UInt64)
    step.ValueRank = -1
    step.Description = ua.LocalizedText('the step index after them')
    return await lockstep.add_method(ua.NodeId(f'{TWIN_OBJECT}/{LOCKSTEP}/Step', index),
                                 ua.QualifiedName('Step', index), call, [n], [step])
