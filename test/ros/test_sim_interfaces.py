"""The twin behind ``simulation_interfaces``: driven only through them (play, pause, stop, step,
query every part, spawn, delete, reset) it reaches the same states, bit for bit, as the same
sequence through its own services; what it cannot do is answered with the interface's result
codes and a message."""

import math
from pathlib import Path
from typing import Any, Dict, List

import numpy as np
import pytest
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile

from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (Bounds, EntityCategory, EntityFilters, Resource, Result,
                                       SimulationState, SimulatorFeatures)
from simulation_interfaces.srv import (DeleteEntity, GetEntities, GetEntitiesStates,
                                       GetEntityInfo, GetEntityState, GetSimulationState,
                                       GetSimulatorFeatures, GetSpawnables, ResetSimulation,
                                       SetSimulationState, SpawnEntity, StepSimulation)

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.entities import delete_part
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.plant.loader import plant_from_mapping
from conveyor_twin.ros.compose import ComposedTwin
from conveyor_twin.ros.plant_cell_node import PlantCellNode
from conveyor_twin.ros.sim_entities import yaw_of
from conveyor_twin.testing import LockstepTwin, wait_for

pytestmark = pytest.mark.ros
WAIT = 120.0  # s, a bound for a loaded machine, not a speed requirement
SEED = 7
OK = Result.RESULT_OK
PLAYING, PAUSED, STOPPED = (SimulationState.STATE_PLAYING, SimulationState.STATE_PAUSED,
                            SimulationState.STATE_STOPPED)
SPAWN_AT = (1.0, 0.1, 0.4)  # x [m], y [m], yaw [rad] of the spawned part


class SimClient:
    """Calls the simulation interfaces of a twin from a node of its own."""

    SERVICES = {'get_simulator_features': GetSimulatorFeatures,
                'get_simulation_state': GetSimulationState,
                'set_simulation_state': SetSimulationState, 'step_simulation': StepSimulation,
                'reset_simulation': ResetSimulation, 'get_entities': GetEntities,
                'get_entity_info': GetEntityInfo, 'get_entity_state': GetEntityState,
                'get_entities_states': GetEntitiesStates, 'get_spawnables': GetSpawnables,
                'spawn_entity': SpawnEntity, 'delete_entity': DeleteEntity}

    def __init__(self, context, namespace: str = '') -> None:
        self.node = Node('sim_client', namespace=namespace or '/', context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.clients = {name: self.node.create_client(kind, name)
                        for name, kind in self.SERVICES.items()}
        self.action = ActionClient(self.node, SimulateSteps, 'simulate_steps')
        # The feedback as the action's topic carries it: rclpy drops a goal's feedback
        # callback once its result is in, and the last feedback may arrive after the result.
        self.feedback: List[Any] = []
        self.node.create_subscription(SimulateSteps.Impl.FeedbackMessage,
                                      'simulate_steps/_action/feedback', self.feedback.append,
                                      QoSProfile(depth=1000))
        for name, client in self.clients.items():
            assert client.wait_for_service(timeout_sec=WAIT), f'{name} not served'
        assert self.action.wait_for_server(timeout_sec=WAIT)

    def complete(self, future) -> Any:
        self.executor.spin_until_future_complete(future, timeout_sec=WAIT)
        assert future.done(), 'no answer within the time budget'
        return future.result()

    def call(self, name: str, **fields: Any) -> Any:
        kind = self.SERVICES[name]
        return self.complete(self.clients[name].call_async(kind.Request(**fields)))

    def set_state(self, state: int) -> Result:
        return self.call('set_simulation_state', state=SimulationState(state=state)).result

    def state(self) -> int:
        return self.call('get_simulation_state').state.state

    def step(self, steps: int) -> None:
        assert self.call('step_simulation', steps=steps).result.result == OK

    def parts(self) -> Dict[str, Any]:
        """Every part's state by entity name."""
        answer = self.call('get_entities_states', filters=EntityFilters(filter='^part_'))
        assert answer.result.result == OK, answer.result.error_message
        return dict(zip(answer.entities, answer.states))

    def close(self) -> None:
        self.action.destroy()
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self.executor.shutdown()


def same_parts(states: Dict[str, Any], reference) -> None:
    """Assert that the interface's states are the reference parts' (bit-equal poses and
    velocities; the orientation the quaternion of the reference yaw)."""
    assert sorted(states) == sorted(f'part_{i}' for i in reference.id.tolist())
    assert len(states) > 0
    for k, part_id in enumerate(reference.id.tolist()):
        s = states[f'part_{part_id}']
        assert s.header.frame_id == 'cell'
        got = (s.pose.position.x, s.pose.position.y, s.twist.linear.x, s.twist.linear.y,
               s.twist.angular.z, s.pose.orientation.z, s.pose.orientation.w)
        yaw = float(reference.yaw[k])
        want = (float(reference.x[k]), float(reference.y[k]), float(reference.vx[k]),
                float(reference.vy[k]), float(reference.wz[k]), math.sin(yaw / 2),
                math.cos(yaw / 2))
        assert got == want, part_id


def quaternion_z(yaw: float) -> Dict[str, float]:
    return {'x': 0.0, 'y': 0.0, 'z': math.sin(yaw / 2), 'w': math.cos(yaw / 2)}


def spawn_request(part_type: str, x: float, y: float, yaw: float, **extra: Any) -> Dict:
    pose = PoseStamped(pose=Pose(position=Point(x=x, y=y), orientation=Quaternion(
        **quaternion_z(yaw))))
    pose.header.frame_id = extra.pop('frame_id', 'cell')
    fields = dict(allow_renaming=True, initial_pose=pose)
    if hasattr(SpawnEntity.Request(), 'entity_resource'):  # the definitions of 2.x
        fields['entity_resource'] = Resource(uri=part_type)
    else:  # those of ROS 2 Jazzy and Kilted
        fields['uri'] = part_type
    fields.update(extra)
    return fields


def simulate(client: SimClient, steps: int) -> List[int]:
    """Run ``simulate_steps``; return the completed steps of every feedback."""
    goal = client.complete(client.action.send_goal_async(SimulateSteps.Goal(steps=steps)))
    assert goal.accepted
    result = client.complete(goal.get_result_async()).result
    assert result.result.result == OK, result.result.error_message

    def feedback() -> List[int]:
        return [m.feedback.completed_steps for m in client.feedback
                if bytes(m.goal_id.uuid) == bytes(goal.goal_id.uuid)]
    # feedback travels on a topic of its own: the last may arrive after the result
    assert wait_for(lambda: feedback() and feedback()[-1] == steps, WAIT, client.executor)
    return feedback()


def test_driven_only_through_the_interfaces_it_reaches_the_states_of_its_own_services(
        ros_context):
    cell = load_cell()
    subject = ComposedTwin(cell, seed=SEED, mode=TimeMode.FAST, context=ros_context,
                           namespace='/subject', markers_rate=0.0)
    subject.start()
    client = SimClient(ros_context, '/subject')
    try:
        features = client.call('get_simulator_features').features.features
        f = SimulatorFeatures
        for code in (f.SPAWNING, f.DELETING, f.ENTITY_STATE_GETTING, f.SIMULATION_RESET,
                     f.SIMULATION_STATE_PAUSE, f.STEP_SIMULATION_MULTIPLE,
                     f.STEP_SIMULATION_ACTION, f.SPAWNABLES):
            assert code in features
        assert f.ENTITY_STATE_SETTING not in features
        assert f.SPAWNING_RESOURCE_STRING not in features
        # play, pause: the clock holds
        assert client.state() == PLAYING
        assert client.set_state(PLAYING).result == (
            SetSimulationState.Response.ALREADY_IN_TARGET_STATE)
        assert client.set_state(PAUSED).result == OK and client.state() == PAUSED
        held = client.call('get_entity_state', entity='belt_main').state.header.stamp
        assert client.call('get_entity_state', entity='belt_main').state.header.stamp == held
        assert client.set_state(PLAYING).result == OK

        def stamp():
            s = client.call('get_entity_state', entity='belt_main').state.header.stamp
            return (s.sec, s.nanosec)
        moved = stamp()
        assert wait_for(lambda: stamp() > moved, WAIT)  # it plays again
        # stopped is paused at step 0; then step through the interfaces only
        assert client.set_state(STOPPED).result == OK and client.state() == STOPPED
        assert client.set_state(PAUSED).result == OK
        client.step(500)
        after_500 = client.parts()
        x, y, yaw = SPAWN_AT
        spawned = client.call('spawn_entity', **spawn_request('spacer', x, y, yaw))
        assert spawned.result.result == OK, spawned.result.error_message
        feedback = simulate(client, 250)
        assert feedback == [100, 200, 250]  # a feedback per chunk
        after_spawn = client.parts()
        assert spawned.entity_name in after_spawn
        deleted = client.call('delete_entity', entity=spawned.entity_name)
        assert deleted.result.result == OK, deleted.result.error_message
        client.step(200)
        after_delete = client.parts()
        assert spawned.entity_name not in after_delete
        assert client.call('reset_simulation').result.result == OK
        client.step(300)
        after_reset = client.parts()
    finally:
        client.close()
        subject.stop()
    subject.health.raise_if_failed()
    with LockstepTwin(cell, seed=SEED) as reference:
        reference.step(500)
        same_parts(after_500, reference.parts())
        # the interface passes the yaw of the quaternion it was given
        ids = reference.spawn('spacer', [x], [y], [yaw_of(**quaternion_z(yaw))])
        assert spawned.entity_name == f'part_{ids[0]}'
        reference.step(250)
        same_parts(after_spawn, reference.parts())
        with reference.composed.twin.lock:
            delete_part(reference.composed.micro_stage, int(ids[0]))
        reference.step(200)
        same_parts(after_delete, reference.parts())
        reference.reset()
        reference.step(300)
        same_parts(after_reset, reference.parts())


def test_a_lockstep_twin_is_paused_steps_on_request_and_answers_what_it_cannot_do():
    with LockstepTwin(seed=SEED) as twin:
        client = SimClient(twin.context)
        try:
            check_lockstep_answers(twin, client)
        finally:
            client.close()


def check_lockstep_answers(twin: LockstepTwin, client: SimClient) -> None:
    composed = twin.composed
    assert client.state() == PAUSED
    refused = client.set_state(PLAYING)
    assert refused.result == SetSimulationState.Response.STATE_TRANSITION_ERROR
    assert 'lockstep' in refused.error_message
    assert client.set_state(SimulationState.STATE_QUITTING).result == (
        Result.RESULT_FEATURE_UNSUPPORTED)
    client.step(600)
    assert composed.twin.step_index == 600
    assert client.call('step_simulation', steps=0).result.result == (
        Result.RESULT_OPERATION_FAILED)
    # entities: parts, belts, actuators, light barriers; filters
    names = client.call('get_entities').entities
    assert {'belt_main', 'actuator_pusher', 'light_barrier_lb_exit'} <= set(names)
    parts = [n for n in names if n.startswith('part_')]
    assert parts
    static = client.call('get_entities', filters=EntityFilters(categories=[EntityCategory(
        category=EntityCategory.CATEGORY_STATIC_OBJECT)])).entities
    assert 'belt_main' in static and not any(n.startswith('part_') for n in static)
    info = client.call('get_entity_info', entity=parts[0])
    assert info.result.result == OK and info.info.tags == ['part', 'spacer']
    bad_regex = client.call('get_entities', filters=EntityFilters(filter='('))
    assert bad_regex.result.result == Result.RESULT_OPERATION_FAILED
    assert 'filters.filter' in bad_regex.result.error_message
    hull = client.call('get_entities', filters=EntityFilters(bounds=Bounds(
        type=Bounds.TYPE_CONVEX_HULL)))
    assert hull.result.result == Result.RESULT_FEATURE_UNSUPPORTED
    unknown = client.call('get_entity_state', entity='part_999999')
    assert unknown.result.result == Result.RESULT_NOT_FOUND
    spawnables = client.call('get_spawnables').spawnables
    assert [getattr(s, 'entity_resource', s).uri for s in spawnables] == ['spacer']
    # spawning: an invalid pose is refused with the twin's message, nothing spawned
    before = len(client.call('get_entities').entities)
    off = client.call('spawn_entity', **spawn_request('spacer', 1.0, 0.6, 0.0))
    assert off.result.result == SpawnEntity.Response.INVALID_POSE
    assert 'is not on a belt' in off.result.error_message
    tilted = spawn_request('spacer', 1.0, 0.0, 0.0)
    tilted['initial_pose'].pose.orientation.x = 1.0
    tilted['initial_pose'].pose.orientation.w = 0.0
    assert client.call('spawn_entity', **tilted).result.result == (
        SpawnEntity.Response.INVALID_POSE)
    assert client.call('spawn_entity', **spawn_request('bolt', 1.0, 0.0, 0.0)).result.result == (
        Result.RESULT_NOT_FOUND)
    assert client.call('spawn_entity', **spawn_request(
        'spacer', 1.0, 0.0, 0.0, frame_id='map')).result.result == (
        SpawnEntity.Response.INVALID_POSE)
    assert client.call('spawn_entity', **spawn_request(
        'spacer', 1.0, 0.0, 0.0, allow_renaming=False)).result.result == (
        SpawnEntity.Response.NAME_INVALID)
    assert len(client.call('get_entities').entities) == before
    # deleting: parts only
    assert client.call('delete_entity', entity='belt_main').result.result == (
        Result.RESULT_OPERATION_FAILED)
    assert client.call('delete_entity', entity='part_999999').result.result == (
        Result.RESULT_NOT_FOUND)
    composed.coordinator.call_listeners.append(lambda *call: None)  # as a recorder does
    recording = client.call('delete_entity', entity=parts[0]).result
    assert recording.result == Result.RESULT_OPERATION_FAILED and 'records' in (
        recording.error_message)
    composed.coordinator.call_listeners.pop()
    assert client.call('delete_entity', entity=parts[0]).result.result == OK
    assert client.call('get_entity_state', entity=parts[0]).result.result == (
        Result.RESULT_NOT_FOUND)
    assert composed.assembled.micro_counters()['deleted'] == 1  # and counted as left
    partial = client.call('reset_simulation', scope=ResetSimulation.Request.SCOPE_TIME)
    assert partial.result.result == Result.RESULT_FEATURE_UNSUPPORTED
    # the action: a cancel is honoured between chunks
    feedback: List[int] = []
    goal = client.complete(client.action.send_goal_async(
        SimulateSteps.Goal(steps=10**9),
        feedback_callback=lambda msg: feedback.append(msg.feedback.completed_steps)))
    assert goal.accepted
    assert wait_for(lambda: len(feedback) >= 1, WAIT, client.executor)
    client.complete(goal.cancel_goal_async())
    result = client.complete(goal.get_result_async())
    assert result.result.result.result == OK and 'canceled' in result.result.result.error_message
    assert 600 < composed.twin.step_index < 600 + 10**9
    # stopped: reset to step 0; stepping needs paused
    assert client.set_state(STOPPED).result == OK and composed.twin.step_index == 0
    assert client.call('step_simulation', steps=1).result.result == Result.RESULT_OPERATION_FAILED
    assert client.set_state(PAUSED).result == OK
    client.step(1)
    assert composed.twin.step_index == 1


def test_a_plant_cell_serves_the_queries_and_leaves_stepping_to_the_plant(ros_context):
    res = Path(__file__).resolve().parents[1] / 'resources' / 'plant'
    plant = plant_from_mapping({'plant': {'name': 'solo'},
                                'cells': [{'name': 'only', 'file': 'relay.yaml'}]},
                               str(res / 'solo.yaml'), res)
    node = PlantCellNode(plant, 'only', context=ros_context, mode=TimeMode.FAST, end_step=300)
    node.start()
    client = SimClient(ros_context, '/' + plant.cell('only').namespace)
    try:
        features = client.call('get_simulator_features').features.features
        f = SimulatorFeatures
        assert f.ENTITY_STATE_GETTING in features
        assert not {f.SPAWNING, f.DELETING, f.SIMULATION_RESET, f.SIMULATION_STATE_SETTING,
                    f.STEP_SIMULATION_SINGLE, f.STEP_SIMULATION_ACTION} & set(features)
        assert client.state() == PLAYING
        for name, fields in (('step_simulation', {'steps': 1}), ('reset_simulation', {}),
                             ('delete_entity', {'entity': 'part_1'}),
                             ('spawn_entity', spawn_request('spacer', 0.1, 0.0, 0.0))):
            answer = client.call(name, **fields).result
            assert answer.result == Result.RESULT_FEATURE_UNSUPPORTED, name
            assert 'the plant steps' in answer.error_message
        assert client.set_state(PAUSED).result == Result.RESULT_FEATURE_UNSUPPORTED
        assert client.call('get_entities').result.result == OK
    finally:
        client.close()
        node.stop()


def test_a_failing_step_is_answered_and_reported_to_the_twins_health(ros_context):
    twin = ComposedTwin(load_cell(), seed=1, mode=TimeMode.LOCKSTEP, context=ros_context,
                        namespace='/failing', markers_rate=0.0)

    def broken(n: int = 1):
        raise RuntimeError('injected step failure')
    twin.start()
    client = SimClient(ros_context, '/failing')
    try:
        twin.twin.step = broken
        answer = client.call('step_simulation', steps=3).result
        assert answer.result == Result.RESULT_OPERATION_FAILED
        assert 'injected step failure' in answer.error_message
        goal = client.complete(client.action.send_goal_async(SimulateSteps.Goal(steps=5)))
        result = client.complete(goal.get_result_async()).result
        assert result.result.result == Result.RESULT_OPERATION_FAILED
        names = [f.name for f in twin.health.failures]
        assert names == ['simulation interfaces: step_simulation',
                         'simulation interfaces: simulate_steps']
        assert 'Traceback' in twin.health.failures[0].traceback
    finally:
        client.close()
        twin.stop()


def test_the_split_layout_serves_state_steps_reset_and_spawn_but_no_entities():
    x, y, yaw = SPAWN_AT
    with LockstepTwin(seed=SEED, layout='split') as twin:
        client = SimClient(twin.context)
        try:
            features = set(client.call('get_simulator_features').features.features)
            f = SimulatorFeatures
            assert {f.SPAWNING, f.STEP_SIMULATION_ACTION, f.SIMULATION_RESET} <= features
            assert not {f.DELETING, f.ENTITY_STATE_GETTING, f.ENTITY_TAGS} & features
            for name, fields in (('get_entities', {}), ('get_entity_state', {'entity': 'x'}),
                                 ('delete_entity', {'entity': 'part_1'})):
                answer = client.call(name, **fields).result
                assert answer.result == Result.RESULT_FEATURE_UNSUPPORTED, name
                assert 'micro process' in answer.error_message
            assert client.state() == PAUSED
            client.step(700)
            assert client.call('reset_simulation').result.result == OK
            client.step(300)
            spawned = client.call('spawn_entity', **spawn_request('spacer', x, y, yaw))
            assert spawned.result.result == OK, spawned.result.error_message
            assert simulate(client, 150) == [100, 150]
        finally:
            client.close()
        assert twin.step(1) == 451  # the harness steps on from where the interfaces left it
        split = twin.parts()
    with LockstepTwin(seed=SEED) as reference:
        reference.step(300)
        ids = reference.spawn('spacer', [x], [y], [yaw_of(**quaternion_z(yaw))])
        assert spawned.entity_name == f'part_{ids[0]}'
        reference.step(151)
        composed = reference.parts()
    for field in ('id', 'x', 'y', 'yaw', 'vx', 'vy', 'wz'):
        assert np.array_equal(getattr(split, field), getattr(composed, field)), field
