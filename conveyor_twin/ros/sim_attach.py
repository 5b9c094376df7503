"""Attach the ``simulation_interfaces`` server to a twin's coordinator (or say why not)."""

from typing import Any, Optional

from conveyor_twin.coord.entities import delete_part, snapshot_parts


def _server_class(coordinator: Any) -> Any:
    """Return the server class, or None (logged as a warning on ``coordinator``) if the package
    ``simulation_interfaces`` is not installed."""
    try:
        from conveyor_twin.ros.sim_interfaces import SimulationInterfaces
    except ImportError as exc:
        coordinator.get_logger().warning(f'simulation_interfaces services are not served: {exc}')
        return None
    return SimulationInterfaces


def attach_sim_interfaces(composed: Any, namespace: Optional[str] = None) -> Any:
    """Return the :class:`~conveyor_twin.ros.sim_interfaces.SimulationInterfaces` server of a
    :class:`~conveyor_twin.ros.compose.ComposedTwin` (not started), or None if the package
    ``simulation_interfaces`` is not installed."""
    server = _server_class(composed.coordinator)
    if server is None:
        return None
    micro = composed.micro_stage
    return server(composed.coordinator, parts=lambda: snapshot_parts(micro),
                  delete=lambda part_id: delete_part(micro, part_id),
                  context=composed.context, namespace=namespace)


def attach_split_sim_interfaces(coordinator: Any, context: Any) -> Any:
    """Return the server of the split layout's coordinator node (not started): state, steps,
    reset and spawn; no entities (the parts live in the micro process). None if the package
    is not installed."""
    server = _server_class(coordinator)
    if server is None:
        return None
    return server(coordinator, parts=None, delete=None, context=context)
