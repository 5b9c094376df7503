"""The built ``simulation_interfaces`` package: its types, their RIHS01 hashes and wire bytes.

``interfaces/simulation_interfaces`` holds the definitions of the simulation_interfaces release
each supported distro ships: Jazzy 1.5.1, Kilted 1.6.1 (their .msg/.srv/.action files are
identical; only the version differs). ``make setup`` builds it into the environment.

How the pinned values were obtained and checked:

- ``TYPE_HASHES``: the RIHS01 hashes in the built package's ``share/simulation_interfaces``
  JSON type descriptions, on Jazzy and on Kilted (the same on both: so are the hashes of every
  type they reference). They equal the hashes ``rosidl hash`` (rosidl_generator_type_description
  of Jazzy, 4.6.6, and of Kilted, 4.9.5) computes from the unmodified upstream files at the git
  tags 1.5.1 and 1.6.1, for all 116 types (with requests, responses, events, action parts). The
  hashes of Result, Resource, Bounds, EntityCategory, EntityFilters, TagsFilter, GetEntities (with
  its request, response and event) and SpawnEntity's response also equal those published in
  rosidl-generated C sources of the package (``*__description.c``) in a public repository.
- ``DEFINITIONS_DIGEST``: SHA-256 of every definition with comments and spacing removed (names,
  types, order, constants, default values: what the hash leaves out, too), computed the same way
  from the upstream files at both tags.
"""

import hashlib
import pathlib
import re

import pytest

# What differs between distros is the build against each distro's wheels: all of this is smoke.
pytestmark = pytest.mark.smoke

ROOT = pathlib.Path(__file__).resolve().parents[2]

MESSAGES = ('Bounds', 'EntityCategory', 'EntityFilters', 'EntityInfo', 'EntityState',
            'NamedPose', 'Resource', 'Result', 'SimulationState', 'SimulatorFeatures',
            'SpawnEntity', 'SpawnResult', 'Spawnable', 'TagsFilter', 'WorldResource')
SERVICES = ('DeleteEntity', 'GetAvailableWorlds', 'GetCurrentWorld', 'GetEntities',
            'GetEntitiesStates', 'GetEntityBounds', 'GetEntityInfo', 'GetEntityState',
            'GetNamedPoseBounds', 'GetNamedPoses', 'GetSimulationState', 'GetSimulatorFeatures',
            'GetSpawnables', 'LoadWorld', 'ResetSimulation', 'SetEntityInfo', 'SetEntityState',
            'SetSimulationState', 'SpawnEntities', 'SpawnEntity', 'StepSimulation', 'UnloadWorld')
ACTIONS = ('SimulateSteps',)

# RIHS01 hashes, the same for Jazzy (1.5.1) and Kilted (1.6.1); per distro, should they differ.
_HASHES = {
    'msg/Bounds': 'e8624fe51f0f5548197542697d924c5699ac7198f1e4c68e50c3ca2af73f5b3f',
    'msg/EntityCategory': '43bdf7933fddf75f6970f7a8fe7078524355d821d390b3954bb46ac36c03dfe1',
    'msg/EntityFilters': '8e7b12e8ea062f14c55de4877221fe1b7cd9749665a7ad8a4ab855fc4b148303',
    'msg/EntityInfo': '3b9a2e7fa00f9a59d325b6e47904044c421561a385682027c7fc06c359806319',
    'msg/EntityState': '2e0464a85eb80a939025075d6c20761eca6a4cb9d6baf2c0ba373467c8b598d0',
    'msg/NamedPose': 'b32da2a039b1840f605ec025b7991a18efacac662fac272818d1ae6e2b12bc27',
    'msg/Resource': '2bb1939cf80f8d2f284afba53cbec60b5ff33759bd39b714128ea8867a34c51a',
    'msg/Result': 'cf43a306adff3337a0a47143d8f5689933bc70a30478f13b077dc1fe3bc5ad17',
    'msg/SimulationState': 'bb9f87ccdd98fba113052a512d9801e84ce732d0a2b3c2b0cb281828de36e415',
    'msg/SimulatorFeatures': '8b101c8529bc0ea3dcf056078254768f39832b9ef0adaf93bd5cea96c0de3305',
    'msg/SpawnEntity': '94a349a865ccf673c18c080520299c88c3d8d5f4842ecf1482d6c997ac4b69f9',
    'msg/SpawnResult': 'dbc277304b6c24bfb2a631cea8f52e2b005d583ec0a6c86b11613f5ce6486da1',
    'msg/Spawnable': '8c22025d840e7a05ab31ba56f998b06458b549a9744b4695be25b778829fc176',
    'msg/TagsFilter': '5c3efc51e8ed04c266c09cb4691ec95b964cd410558e01d8c83646b038826b45',
    'msg/WorldResource': 'e3b65ecf904b9b115673e4a343c6aa3d28c19e185a71228faa64b783afcf2403',
    'srv/DeleteEntity': 'ff7e96a5b83dc8e2bb34b8b034480028b3a24d9f8376b2c0590bac3704be3e28',
    'srv/GetAvailableWorlds': 'ce5589b5523f2732d1969a3c5a7e6b17a387091df8190c62f78d7fdd1109e3e3',
    'srv/GetCurrentWorld': '79ed4e910e1b7a1c9f7950ff758bfba3535bf0dec669054e8af115a099724ddd',
    'srv/GetEntities': 'cb90004c48cd50f37732fb008e22c34c261dd680a723bf0f85d8437ea4498bf7',
    'srv/GetEntitiesStates': '0a76170d0c1c90e1eaf805cfab78ea801d1f82df309a28c1f0fae4b570f19754',
    'srv/GetEntityBounds': '17be8d36231178a5eed0de0344b55c19975581627a9aec30a4fee9926a35deed',
    'srv/GetEntityInfo': '953b7ab6bfc35063f5c9a72463c6ce489baa10249a7fa510926d342a34b0d29e',
    'srv/GetEntityState': '749c91f2a2353d98367b64f2995a0f5842ce92a08ec1ffb3e185540a91557fb5',
    'srv/GetNamedPoseBounds': '59fa8dd2c68ba6771160cc66a628ac99fa95e2748fa0a43c2cc62a2e5f3f6fdc',
    'srv/GetNamedPoses': 'c3d12ab920115bfd4733f6d20516adc3968fb438538540997c37e200e02b04e3',
    'srv/GetSimulationState': '3362dcebee4b1afebbf9c4beee5c79c1455385aded62092a892d61fde8644f30',
    'srv/GetSimulatorFeatures':
        'abb9439c8cf196722a469fb6c68b44b484f198c2a1356ac38849a29c2a20a794',
    'srv/GetSpawnables': '3bc0266bf8236058ff589c44512e013afe4f295427c39d44cff363d1c956bf36',
    'srv/LoadWorld': 'f210682338f195f6f06191b46b20ec4992bddf485d33e2cffab2dd15341b4e3e',
    'srv/ResetSimulation': '4ce285d7ff9b8ac70dcc95161f32bf54c05a6f4b13427990e41ab40c36c39646',
    'srv/SetEntityInfo': '867fe2b6812f3e021859171f9b788560d66bb7079d640030baf6c0bb2dd2631e',
    'srv/SetEntityState': 'ca210e7d2b66629ae133c8e1edf5246e618106d75c78ed0556c0e7a33c59ee5e',
    'srv/SetSimulationState': 'a868b916dce49974f637ba252141258c4b07b0c06858b88af560e3eb6bfbcb30',
    'srv/SpawnEntities': '41703a359ee032bf4fc230f144f531705ba039a2e97edeae1f7997dd83b04857',
    'srv/SpawnEntity': 'd4c086345d4194a5fc4c9ae45095736ca4062b5cdac4d06a42dec93d683e03cf',
    'srv/StepSimulation': '913fe0653690ce6bf8f09f316e6a626747012e9fca31e26719910d417aa8565c',
    'srv/UnloadWorld': 'ac7f9a73df1b5b15015d854c5ac552b7726506e22f886c6792804f0b7f88b30b',
    'action/SimulateSteps': 'f0837c898e1219cd73bf4c041feab41e8c533e8e1057e982744dba7b093467eb',
    # Parts whose hash the middleware announces (a service's event, an action's feedback).
    'srv/DeleteEntity_Event': '6850423be1d45755566343794fb56be8ff3c90fc87706b7ea939764499a9d773',
    'srv/SpawnEntity_Event': '05e6108bc39b5953a6163952541a1cec1991a74558a128c65b03b27b3ec34c61',
    'srv/StepSimulation_Event':
        '1796fda54ba381a56d32c10784cabf78e14d6c8a1912a515a47d6597ad431d90',
    'action/SimulateSteps_FeedbackMessage':
        'a30dee7ee7380769e616406ec5067b238aa2b27e1dbd7a5957fba1d908d7754d',
}
TYPE_HASHES = {distro: {f'simulation_interfaces/{name}': f'RIHS01_{value}'
                        for name, value in _HASHES.items()}
               for distro in ('jazzy', 'kilted')}
DEFINITIONS_DIGEST = 'd36c3ba929f50de5bf78ea7d8c45513bb18a3c6eec7e2b4f90158098ed0ddd25'


def _share() -> pathlib.Path:
    from ament_index_python.packages import get_package_share_directory

    return pathlib.Path(get_package_share_directory('simulation_interfaces'))


def _distro() -> str:
    """Return the distro of the running environment (the one whose rclpy pin is installed)."""
    from importlib.metadata import version

    pin = f'ros-rclpy=={version("ros-rclpy")}'
    for distro in TYPE_HASHES:
        if pin in (ROOT / 'requirements' / f'{distro}.txt').read_text().splitlines():
            return distro
    pytest.fail(f'{pin} is pinned by none of requirements/<distro>.txt')


def definitions_digest(root: pathlib.Path) -> str:
    """SHA-256 of the package's definitions without comments, blank lines and extra spaces.

    :param root: directory with msg/, srv/ and action/ (a source tree or the installed share/)
    """
    sha = hashlib.sha256()
    for kind, suffix in (('msg', '.msg'), ('srv', '.srv'), ('action', '.action')):
        for path in sorted((root / kind).glob('*' + suffix)):
            lines = (re.sub(r'\s*=\s*', '=', re.sub(r'\s+', ' ', line.split('#', 1)[0]).strip())
                     for line in path.read_text().splitlines())
            sha.update(f'{kind}/{path.name}\n'.encode())
            sha.update(''.join(f'{line}\n' for line in lines if line).encode())
    return sha.hexdigest()


def test_every_type_imports():
    import simulation_interfaces.action
    import simulation_interfaces.msg
    import simulation_interfaces.srv

    missing = [f'msg/{n}' for n in MESSAGES if not hasattr(simulation_interfaces.msg, n)]
    missing += [f'srv/{n}' for n in SERVICES if not hasattr(simulation_interfaces.srv, n)]
    missing += [f'action/{n}' for n in ACTIONS if not hasattr(simulation_interfaces.action, n)]
    assert not missing


def test_the_package_has_exactly_the_release_types():
    share = _share()
    found = {f'{p.parent.name}/{p.stem}' for kind in ('msg', 'srv', 'action')
             for p in (share / kind).glob('*.idl')}
    assert found == ({f'msg/{n}' for n in MESSAGES} | {f'srv/{n}' for n in SERVICES}
                     | {f'action/{n}' for n in ACTIONS})


def test_type_hashes_equal_the_release():
    import json

    share = _share()
    built = {}
    for path in share.glob('*/*.json'):
        for entry in json.loads(path.read_text()).get('type_hashes', []):
            built[entry['type_name']] = entry['hash_string']
    pinned = TYPE_HASHES[_distro()]
    assert {name: built.get(name) for name in pinned} == pinned


def test_definitions_equal_the_release():
    """Constants, default values, names, types and order (the hash leaves constants and
    defaults out)."""
    assert definitions_digest(_share()) == DEFINITIONS_DIGEST


def test_default_values_and_constants():
    from simulation_interfaces.msg import Result, SimulatorFeatures
    from simulation_interfaces.srv import ResetSimulation, StepSimulation

    assert StepSimulation.Request().steps == 1
    assert (Result.RESULT_OK, SimulatorFeatures.SPAWNING_ENTITIES) == (1, 50)
    assert ResetSimulation.Request.SCOPE_ALL == 255


def test_a_request_round_trips_through_serialization():
    from rclpy.serialization import deserialize_message, serialize_message
    from simulation_interfaces.srv import SpawnEntity, StepSimulation

    request = SpawnEntity.Request(name='box_1', allow_renaming=True, uri='model://box',
                                  entity_namespace='cell')
    request.initial_pose.header.frame_id = 'world'
    request.initial_pose.pose.position.x = 1.25
    request.initial_pose.pose.orientation.z = 0.5
    data = serialize_message(request)
    assert deserialize_message(data, SpawnEntity.Request) == request
    # XCDR1 little endian: encapsulation header, then the uint64.
    assert serialize_message(StepSimulation.Request(steps=7)) == (
        b'\x00\x01\x00\x00' + (7).to_bytes(8, 'little'))


@pytest.mark.ros
def test_the_middleware_announces_the_pinned_hashes(ros_context):
    """The compiled type support carries the hashes: the graph reports them for a message
    publisher, a service's event publisher and an action's feedback publisher."""
    from rclpy.action import ActionServer
    from rclpy.node import Node
    from rclpy.qos import qos_profile_services_default
    from rclpy.service_introspection import ServiceIntrospectionState
    from simulation_interfaces.action import SimulateSteps
    import simulation_interfaces.msg
    import simulation_interfaces.srv

    from conveyor_twin.testing.ros_env import wait_for

    pinned = TYPE_HASHES[_distro()]
    node = Node('simulation_interfaces_hashes', context=ros_context)
    try:
        expected = {}
        for name in MESSAGES:
            topic = f'/hash_check/{name.lower()}'
            node.create_publisher(getattr(simulation_interfaces.msg, name), topic, 1)
            expected[topic] = pinned[f'simulation_interfaces/msg/{name}']
        for name in ('DeleteEntity', 'SpawnEntity', 'StepSimulation'):
            service = node.create_service(getattr(simulation_interfaces.srv, name),
                                          f'/hash_check/{name.lower()}', lambda q, r: r)
            service.configure_introspection(node.get_clock(), qos_profile_services_default,
                                            ServiceIntrospectionState.METADATA)
            expected[f'/hash_check/{name.lower()}/_service_event'] = (
                pinned[f'simulation_interfaces/srv/{name}_Event'])
        ActionServer(node, SimulateSteps, '/hash_check/steps', lambda goal: None)
        expected['/hash_check/steps/_action/feedback'] = (
            pinned['simulation_interfaces/action/SimulateSteps_FeedbackMessage'])

        def announced():
            return {topic: sorted({str(i.topic_type_hash)
                                   for i in node.get_publishers_info_by_topic(topic)})
                    for topic in expected}

        want = {topic: [value] for topic, value in expected.items()}
        wait_for(lambda: announced() == want, timeout=60.0)
        assert announced() == want
    finally:
        node.destroy_node()
