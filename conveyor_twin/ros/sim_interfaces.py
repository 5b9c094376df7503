"""The twin behind ROS 2's ``simulation_interfaces``, beside its own services.

A node ``simulation_interfaces`` in the twin's namespace serves the standard's services and
its action under the names simulators use (relative, so the namespace moves them):
``get_simulator_features``, ``get_simulation_state``, ``set_simulation_state``,
``step_simulation``, ``simulate_steps`` (action), ``reset_simulation``, ``get_entities``,
``get_entity_info``, ``get_entity_state``, ``get_entities_states``, ``get_spawnables``,
``spawn_entity``, ``delete_entity``. Each call converts, calls the twin's own code (the
coordinator's reset and spawn, the :class:`~conveyor_twin.coord.runner.Runner`'s pause and
steps, :mod:`conveyor_twin.coord.entities`) and answers; a request the twin cannot serve is
answered with the interface's result code and a message, never an exception.

Simulation state: a realtime or fast twin plays; paused, its stepping thread holds the clock and
``step_simulation``/``simulate_steps`` step it; ``stopped`` is paused and reset. A lockstep twin
is always paused (it steps on request). The node has an executor of its own (threads that may
serve a cancel while ``simulate_steps`` runs); its failure is reported to the twin's health.
docs/simulation_interfaces.md lists what is supported.
"""

import threading
from typing import Callable, List, Optional

from conveyor_twin_msgs.srv import Reset, SpawnParts
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import Result, SimulationState, SimulatorFeatures
from simulation_interfaces.srv import (DeleteEntity, GetEntities, GetEntitiesStates,
                                       GetEntityInfo, GetEntityState, GetSimulationState,
                                       GetSimulatorFeatures, GetSpawnables, ResetSimulation,
                                       SetSimulationState, SpawnEntity, StepSimulation)

from conveyor_twin.coord import entities
from conveyor_twin.coord.entities import EntityQueryError
from conveyor_twin.micro.state import PartsView
from conveyor_twin.coord.requests import check_spawn, RequestRejected
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.ros.compat import spin_until
from conveyor_twin.ros.sim_entities import (info_of, ok, query_of, Refused, resource_of,
                                            spawn_pose, spawnable, state_of)

#: Name of the executor thread (and of its failure in the twin's health).
EXECUTOR = 'simulation interfaces executor'
#: Threads of the node's executor: a long ``simulate_steps`` and a cancel or query beside it.
THREADS = 3
#: Longest wait of the executor thread between two looks at a stop [s] (few wake-ups beside a
#: realtime stepping thread).
SPIN_PERIOD = 0.25
#: Steps of ``simulate_steps`` between two feedbacks (and two looks at a cancel).
CHUNK = 100
#: Why a twin without parts (the split layout's coordinator) serves no entities.
NO_ENTITIES = ('the parts live in the micro process of the split layout, which answers no '
               'entity queries or deletes; the composed layout serves them')
#: Result code of ``set_simulation_state`` (from its response).
_SET = SetSimulationState.Response
#: The reset scopes the twin's reset covers at once (time, state, spawned).
_FULL_RESET = (ResetSimulation.Request.SCOPE_TIME | ResetSimulation.Request.SCOPE_STATE
               | ResetSimulation.Request.SCOPE_SPAWNED)
_STATE_NAMES = {SimulationState.STATE_STOPPED: 'stopped', SimulationState.STATE_PLAYING: 'playing',
                SimulationState.STATE_PAUSED: 'paused', SimulationState.STATE_QUITTING: 'quitting',
                SimulationState.STATE_NO_WORLD: 'no world',
                SimulationState.STATE_LOADING_WORLD: 'loading world'}


class SimulationInterfaces:
    """The ``simulation_interfaces`` server of one twin.

    :param coordinator: the twin's coordinator node (its twin, runner, reset and spawn).
    :param parts: returns a snapshot of the micro parts (called with the twin's lock held);
        None: the entities are not served (the split layout's coordinator has no parts).
    :param delete: deletes a part by id now (called with the twin's lock held); raises
        KeyError if the micro scale does not hold it. None: deleting is not supported.
    :param context: the twin's rclpy context. :param namespace: the twin's namespace.
    """

    def __init__(self, coordinator, *, parts: Optional[Callable[[], PartsView]],
                 delete: Optional[Callable[[int], None]], context,
                 namespace: Optional[str] = None) -> None:
        self.coordinator = coordinator
        self.twin = coordinator.twin
        self.runner = coordinator.runner
        self._parts = parts
        self._delete = delete
        #: Why stepping, state changes, reset, spawn and delete are refused ('' : they are not).
        self.control_refusal = ''
        self._control = threading.Lock()  # one state change or stepping at a time
        self._stopped = False
        group = ReentrantCallbackGroup()
        self.node = Node('simulation_interfaces', namespace=namespace, context=context)
        services = (
            (GetSimulatorFeatures, 'get_simulator_features', self._on_features),
            (GetSimulationState, 'get_simulation_state', self._on_get_state),
            (SetSimulationState, 'set_simulation_state', self._on_set_state),
            (StepSimulation, 'step_simulation', self._on_step),
            (ResetSimulation, 'reset_simulation', self._on_reset),
            (GetEntities, 'get_entities', self._on_get_entities),
            (GetEntityInfo, 'get_entity_info', self._on_get_entity_info),
            (GetEntityState, 'get_entity_state', self._on_get_entity_state),
            (GetEntitiesStates, 'get_entities_states', self._on_get_entities_states),
            (GetSpawnables, 'get_spawnables', self._on_get_spawnables),
            (SpawnEntity, 'spawn_entity', self._on_spawn),
            (DeleteEntity, 'delete_entity', self._on_delete))
        self._services = [self.node.create_service(kind, name,
                                                   self._answering(callback, kind, name),
                                                   callback_group=group)
                          for kind, name, callback in services]
        self._action = ActionServer(self.node, SimulateSteps, 'simulate_steps',
                                    self._simulate_steps, callback_group=group,
                                    goal_callback=lambda goal: GoalResponse.ACCEPT,
                                    cancel_callback=lambda handle: CancelResponse.ACCEPT)
        self.executor = MultiThreadedExecutor(num_threads=THREADS, context=context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    # -- life cycle ----------------------------------------------------------------------
    def start(self) -> None:
        """Start serving (a thread of its own; its failure goes to the twin's health)."""
        self._thread = self.twin.health.thread(EXECUTOR, spin_until, self.executor, self._stop,
                                               SPIN_PERIOD)
        self._thread.start()

    def stop(self) -> None:
        """Stop serving and destroy the node (once)."""
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.executor.shutdown(timeout_sec=5.0)
        self._action.destroy()
        self.node.destroy_node()

    def refuse_control(self, reason: str) -> None:
        """Serve the queries only: refuse stepping, state changes, reset, spawn and delete
        with ``reason`` (a plant cell, which the plant steps)."""
        self.control_refusal = reason

    # -- what the twin supports ----------------------------------------------------------
    def features(self) -> List[int]:
        """Return the interface's feature codes this twin serves."""
        f = SimulatorFeatures
        out = [f.SPAWNABLES, f.SIMULATION_STATE_GETTING]
        if self._parts is not None:
            out += [f.ENTITY_TAGS, f.ENTITY_BOUNDS_BOX, f.ENTITY_CATEGORIES,
                    f.ENTITY_STATE_GETTING, f.ENTITY_INFO_GETTING]
        if not self.control_refusal:
            out += [f.SPAWNING, f.SIMULATION_RESET, f.SIMULATION_STATE_SETTING,
                    f.SIMULATION_STATE_PAUSE, f.STEP_SIMULATION_SINGLE,
                    f.STEP_SIMULATION_MULTIPLE, f.STEP_SIMULATION_ACTION]
            if self._delete is not None:
                out.append(f.DELETING)
        return sorted(out)

    def state(self) -> int:
        """Return the simulation state: stopped, paused (lockstep: always, unless stopped) or
        playing (the stepping thread runs; a plant cell, which the plant steps)."""
        if self.control_refusal:
            return SimulationState.STATE_PLAYING
        if self._stopped and self.twin.step_index == 0:  # until anything steps it
            return SimulationState.STATE_STOPPED
        if self.runner.mode is TimeMode.LOCKSTEP or self.runner.paused:
            return SimulationState.STATE_PAUSED
        if self.runner.running:
            return SimulationState.STATE_PLAYING
        return SimulationState.STATE_PAUSED  # not started yet, or the run ended

    # -- service plumbing ----------------------------------------------------------------
    def _answering(self, callback: Callable, kind, name: str) -> Callable:
        """Wrap a handler: a :class:`Refused` becomes the response's result; any other
        exception (a failing step, a defect) is reported to the twin's health and answered
        with an OPERATION_FAILED result naming it."""
        def serve(request, response):
            try:
                callback(request, response)
            except Refused as exc:
                response = kind.Response()
                response.result = exc.result()
            except Exception as exc:  # noqa: BLE001 - reported, and answered
                self.twin.health.report(f'simulation interfaces: {name}', exc)
                if not hasattr(kind.Response, 'result'):
                    raise
                response = kind.Response()
                response.result = Result(result=Result.RESULT_OPERATION_FAILED,
                                         error_message=f'{type(exc).__name__}: {exc}')
            return response
        return serve

    def _check_control(self, what: str) -> None:
        if self.control_refusal:
            raise Refused(Result.RESULT_FEATURE_UNSUPPORTED, f'{what}: {self.control_refusal}')

    # -- simulation state ----------------------------------------------------------------
    def _on_features(self, request, response) -> None:
        response.features.features = self.features()
        response.features.spawn_formats = []
        response.features.custom_info = (
            'conveyor_twin: spawn a part type by its name as uri (get_spawnables); entities '
            'are part_<id>, belt_<name>, actuator_<name>, light_barrier_<name>; poses in the '
            'cell frame '
            f'{self.twin.cell.settings.frame_id!r}')

    def _on_get_state(self, request, response) -> None:
        response.state.state = self.state()
        response.result = ok()

    def _on_set_state(self, request, response) -> None:
        target = request.state.state
        self._check_control('set_simulation_state')
        with self._control:
            current = self.state()
            if target == current:
                raise Refused(_SET.ALREADY_IN_TARGET_STATE,
                              f'the simulation is already {_STATE_NAMES[current]}')
            if target not in (SimulationState.STATE_STOPPED, SimulationState.STATE_PLAYING,
                              SimulationState.STATE_PAUSED):
                name = _STATE_NAMES.get(target, f'state {target}')
                raise Refused(Result.RESULT_FEATURE_UNSUPPORTED,
                              f'set_simulation_state {name}: the twin sets stopped, playing '
                              'and paused only')
            if target == SimulationState.STATE_PLAYING:
                self._play()
            elif current == SimulationState.STATE_PLAYING:
                self.runner.pause()
            if target == SimulationState.STATE_STOPPED:
                self._reset()
            self._stopped = target == SimulationState.STATE_STOPPED
        response.result = ok(f'the simulation is {_STATE_NAMES[target]}')

    def _play(self) -> None:
        if self.runner.mode is TimeMode.LOCKSTEP:
            raise Refused(_SET.STATE_TRANSITION_ERROR,
                          'a lockstep twin does not play: it steps on request '
                          '(step_simulation, simulate_steps, step); run it in realtime or '
                          'fast mode to play and pause')
        if not self.runner.resume() and not self.runner.running:
            raise Refused(_SET.STATE_TRANSITION_ERROR,
                          'the stepping thread is not running (not started yet, or the run '
                          'ended)')

    def _on_step(self, request, response) -> None:
        self._check_control('step_simulation')
        steps = int(request.steps)
        with self._control:
            self._check_paused('step_simulation', steps)
            self.runner.step(steps)
        response.result = ok(f'stepped {steps} step(s) to step {self.twin.step_index}')

    def _check_paused(self, what: str, steps: int) -> None:
        state = self.state()
        if state != SimulationState.STATE_PAUSED:
            raise Refused(Result.RESULT_OPERATION_FAILED,
                          f'{what}: the simulation is {_STATE_NAMES[state]}; it steps only '
                          'when paused (set_simulation_state paused)')
        if steps < 1:
            raise Refused(Result.RESULT_OPERATION_FAILED,
                          f'{what}: steps {steps}: expected at least 1')

    def _simulate_steps(self, goal_handle) -> SimulateSteps.Result:
        """Step ``steps`` in chunks of :data:`CHUNK`, feedback after each, a cancel honoured
        between chunks."""
        total = int(goal_handle.request.steps)
        result = SimulateSteps.Result()
        done = 0
        try:
            self._check_control('simulate_steps')
            with self._control:
                self._check_paused('simulate_steps', total)
            while done < total:
                if goal_handle.is_cancel_requested:
                    goal_handle.canceled()
                    result.result = ok(f'canceled after {done} of {total} steps')
                    return result
                n = min(CHUNK, total - done)
                with self._control:
                    self._check_paused('simulate_steps', n)
                    self.runner.step(n)
                done += n
                goal_handle.publish_feedback(SimulateSteps.Feedback(
                    completed_steps=done, remaining_steps=total - done))
        except Refused as exc:
            goal_handle.abort()
            result.result = exc.result()
            return result
        except Exception as exc:  # noqa: BLE001 - a failing step: reported, and answered
            self.twin.health.report('simulation interfaces: simulate_steps', exc)
            goal_handle.abort()
            result.result = Result(result=Result.RESULT_OPERATION_FAILED,
                                   error_message=f'{type(exc).__name__}: {exc}')
            return result
        goal_handle.succeed()
        result.result = ok(f'stepped {total} step(s) to step {self.twin.step_index}')
        return result

    def _on_reset(self, request, response) -> None:
        self._check_control('reset_simulation')
        scope = request.scope
        if scope not in (ResetSimulation.Request.SCOPE_DEFAULT,
                         ResetSimulation.Request.SCOPE_ALL) and scope & _FULL_RESET != _FULL_RESET:
            raise Refused(Result.RESULT_FEATURE_UNSUPPORTED,
                          f'reset_simulation scope {scope}: the twin resets time, state and '
                          f'spawned parts together (scope {ResetSimulation.Request.SCOPE_DEFAULT}'
                          f', {_FULL_RESET} or {ResetSimulation.Request.SCOPE_ALL})')
        with self._control:
            response.result = ok(self._reset())

    def _reset(self) -> str:
        """The twin's own reset (seed and cell as now)."""
        answer = self.coordinator.reset_twin(Reset.Request(seed=self.twin.seed, cell_file=''))
        if not answer.success:
            raise Refused(Result.RESULT_OPERATION_FAILED, answer.message)
        return answer.message

    # -- entities ------------------------------------------------------------------------
    def _snapshot(self):
        """Return (parts, actuator positions, sim time [ns]) of one step."""
        if self._parts is None:
            raise Refused(Result.RESULT_FEATURE_UNSUPPORTED, NO_ENTITIES)
        with self.twin.lock:
            return (self._parts(), self.twin.actuation.actuator_position.copy(),
                    self.twin.time_ns)

    def _select(self, filters):
        """Return (selected entities, parts, actuator positions, time [ns])."""
        query = query_of(filters)
        parts, positions, time_ns = self._snapshot()
        cell = self.twin.cell
        try:
            chosen = query.select(cell, entities.list_entities(cell, parts), parts, positions)
        except EntityQueryError as exc:
            raise Refused(Result.RESULT_OPERATION_FAILED, str(exc)) from None
        return chosen, parts, positions, time_ns

    def _find(self, name: str, parts):
        entity = entities.find_entity(self.twin.cell, parts, name)
        if entity is None:
            raise Refused(Result.RESULT_NOT_FOUND, f'no entity {name!r} (parts are part_<id>, '
                          'while the micro scale holds them; get_entities lists every entity)')
        return entity

    def _on_get_entities(self, request, response) -> None:
        chosen = self._select(request.filters)[0]
        response.entities = [e.name for e in chosen]
        response.result = ok()

    def _on_get_entities_states(self, request, response) -> None:
        chosen, parts, positions, time_ns = self._select(request.filters)
        frame = self.twin.cell.settings.frame_id
        response.entities = [e.name for e in chosen]
        response.states = [state_of(entities.entity_state(self.twin.cell, e, parts, positions),
                                    frame, time_ns) for e in chosen]
        response.result = ok()

    def _on_get_entity_info(self, request, response) -> None:
        parts = self._snapshot()[0]
        response.info = info_of(self._find(request.entity, parts))
        response.result = ok()

    def _on_get_entity_state(self, request, response) -> None:
        parts, positions, time_ns = self._snapshot()
        entity = self._find(request.entity, parts)
        response.state = state_of(entities.entity_state(self.twin.cell, entity, parts,
                                                        positions),
                                  self.twin.cell.settings.frame_id, time_ns)
        response.result = ok()

    def _on_get_spawnables(self, request, response) -> None:
        response.spawnables = [spawnable(p.name, f'{p.shape} part {p.name!r}, {p.mass:g} kg')
                               for p in self.twin.cell.part_types]
        unknown = list(request.sources)
        response.result = ok(f'sources not searched (the twin spawns its part types only): '
                             f'{unknown}' if unknown else '')

    def _on_spawn(self, request, response) -> None:
        self._check_control('spawn_entity')
        cell = self.twin.cell
        uri, resource_string = resource_of(request)
        if not uri:
            if resource_string:
                raise Refused(Result.RESULT_FEATURE_UNSUPPORTED,
                              'resource_string is not supported: give a part type as uri '
                              '(get_spawnables)')
            raise Refused(SpawnEntity.Response.NO_RESOURCE,
                          'uri is empty: give a part type (get_spawnables)')
        if request.entity_namespace:
            raise Refused(SpawnEntity.Response.NAMESPACE_INVALID,
                          f'entity_namespace {request.entity_namespace!r}: parts have no '
                          'interfaces of their own; leave it empty')
        if not request.allow_renaming:
            raise Refused(SpawnEntity.Response.NAME_INVALID,
                          f'name {request.name!r}: the twin names parts part_<id> itself; set '
                          'allow_renaming and read entity_name')
        x, y, yaw = spawn_pose(cell, request.initial_pose)
        try:
            cell.part_type_index(uri)
        except KeyError:
            raise Refused(Result.RESULT_NOT_FOUND,
                          f'uri {uri!r}: no such part type (spawnables: '
                          + ', '.join(p.name for p in cell.part_types) + ')') from None
        try:
            check_spawn(cell, uri, [x], [y], [yaw])
        except RequestRejected as exc:
            raise Refused(SpawnEntity.Response.INVALID_POSE, str(exc)) from None
        with self._control:
            answer = self.coordinator.spawn_parts(
                SpawnParts.Request(part_type=uri, x=[x], y=[y], yaw=[yaw]))
        if not answer.success:  # placed nowhere: overlaps a part or an actuator, or full
            raise Refused(Result.RESULT_OPERATION_FAILED, answer.message)
        response.entity_name = entities.part_name(answer.id[0])
        response.result = ok(answer.message)

    def _on_delete(self, request, response) -> None:
        self._check_control('delete_entity')
        if self._delete is None:
            raise Refused(Result.RESULT_FEATURE_UNSUPPORTED,
                          NO_ENTITIES if self._parts is None
                          else 'delete_entity is not supported by this layout')
        if self.coordinator.call_listeners:
            raise Refused(Result.RESULT_OPERATION_FAILED,
                          'delete_entity is refused while the twin records: a recording has '
                          'no deletes, it would not re-simulate')
        name = request.entity
        with self._control, self.twin.lock:
            entity = self._find(name, self._parts())
            if entity.kind != entities.PART:
                raise Refused(Result.RESULT_OPERATION_FAILED,
                              f'{name!r} is a {entity.kind.replace("_", " ")} of the cell; only '
                              'parts can be deleted')
            self._delete(entity.index)
        response.result = ok(f'deleted {name} (counted as left)')
