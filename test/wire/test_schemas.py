"""Schema texts against msg_defs and the installed packages; RIHS01 hashes against rosidl's."""

import json
import pathlib
import re
import sys

from mcap.records import Schema
import mcap_ros2.decoder
import pytest

from conveyor_twin.wire import schemas
from conveyor_twin.wire.typehash import type_hash

# Type hashes and schema texts are what differs between distros: all of this is smoke.
pytestmark = pytest.mark.smoke

ROOT = pathlib.Path(__file__).resolve().parents[2]
MSG_DEFS = ROOT / 'msg_defs' / 'msg'
# The share/ of the environment running the tests (its distro's installed packages).
SHARE_DIRS = [pathlib.Path(sys.prefix) / 'share']


def significant_lines(text):
    """Return the lines of a .msg text without comments, blank lines and extra spaces."""
    lines = (re.sub(r'\s+', ' ', line.split('#', 1)[0]).strip() for line in text.splitlines())
    return [line for line in lines if line]


@pytest.mark.parametrize('type_name', schemas.CONTRACT_TYPES)
def test_contract_texts_equal_msg_defs(type_name):
    path = MSG_DEFS / (type_name.split('/')[-1] + '.msg')
    if not path.exists():
        pytest.skip(f'{path} does not exist (yet)')
    assert schemas.MSG_TEXTS[type_name] == path.read_text()


def test_every_msg_def_is_known():
    if not MSG_DEFS.is_dir():
        pytest.skip('msg_defs/msg does not exist (yet)')
    names = {f'conveyor_twin_msgs/msg/{p.stem}' for p in MSG_DEFS.glob('*.msg')}
    assert names == set(schemas.CONTRACT_TYPES)


def test_contract_fields_in_order():
    fields = schemas.parse_fields('conveyor_twin_msgs/msg/PartStates',
                                  schemas.MSG_TEXTS['conveyor_twin_msgs/msg/PartStates'])
    assert [(f.name, f.base, f.array) for f in fields] == [
        ('header', 'std_msgs/msg/Header', ''), ('step', 'uint64', ''),
        ('id', 'uint32', 'unbounded'), ('part_type', 'uint16', 'unbounded'),
        *[(n, 'float64', 'unbounded') for n in ('x', 'y', 'yaw', 'vx', 'vy', 'wz')]]


def test_parse_fields_skips_constants_and_reads_bounds():
    text = 'byte OK=0\nint32 X = 3\nstring<=8 s\nfloat64[3] a\nuint8[<=4] b  # c\nFoo f\n'
    fields = schemas.parse_fields('pkg/msg/T', text)
    assert [(f.name, f.base, f.array, f.capacity, f.string_capacity) for f in fields] == [
        ('s', 'string', '', 0, 8), ('a', 'float64', 'fixed', 3, 0),
        ('b', 'uint8', 'bounded', 4, 0), ('f', 'pkg/msg/Foo', '', 0, 0)]


def test_concatenation_follows_rosbag2():
    text = schemas.SCHEMAS['diagnostic_msgs/msg/DiagnosticArray']
    headers = re.findall(r'^MSG: (.*)$', text, flags=re.M)
    # rosbag2 visits each type's dependencies sorted by name, depth first
    assert headers == ['diagnostic_msgs/DiagnosticStatus', 'diagnostic_msgs/KeyValue',
                       'std_msgs/Header', 'builtin_interfaces/Time']
    assert '\n' + '=' * 80 + '\nMSG: std_msgs/Header\n' in text
    parts = schemas.SCHEMAS['conveyor_twin_msgs/msg/PartStates'].split('=' * 80 + '\n')
    assert parts[0] == schemas.MSG_TEXTS['conveyor_twin_msgs/msg/PartStates'] + '\n'


@pytest.mark.parametrize('type_name', sorted(schemas.SCHEMAS))
def test_schemas_parse_with_mcap_ros2(type_name):
    schema = Schema(id=1, name=type_name, encoding='ros2msg',
                    data=schemas.SCHEMAS[type_name].encode())
    assert mcap_ros2.decoder.DecoderFactory().decoder_for('cdr', schema) is not None


@pytest.mark.parametrize('type_name', sorted(schemas.MSG_TEXTS))
def test_standard_texts_and_hashes_match_installed_packages(type_name):
    pkg, _, name = type_name.split('/')
    for share in SHARE_DIRS:
        msg = share / pkg / 'msg' / f'{name}.msg'
        description = share / pkg / 'msg' / f'{name}.json'
        if msg.exists() and description.exists():
            break
    else:
        pytest.skip(f'{type_name} is not installed in {SHARE_DIRS}')
    if not type_name.startswith('conveyor_twin_msgs/'):
        # The recorded schema text is Kilted's; Jazzy's builtin_interfaces Time and Duration
        # differ from it in comments only (which neither decoding nor the type hash reads).
        assert significant_lines(schemas.MSG_TEXTS[type_name]) == \
            significant_lines(msg.read_text())
    hashes = json.loads(description.read_text())['type_hashes']
    assert type_hash(type_name) == hashes[0]['hash_string']
    assert hashes[0]['type_name'] == type_name


def test_type_hash_known_value():
    # std_msgs/msg/Header of Jazzy/Kilted (share/std_msgs/msg/Header.json)
    assert type_hash('std_msgs/msg/Header') == (
        'RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01')


@pytest.mark.parametrize('name', ['SpawnParts', 'Reset'])
def test_recorded_service_requests_equal_msg_defs(name):
    path = MSG_DEFS.parent / 'srv' / f'{name}.srv'
    request = path.read_text().split('---')[0]
    assert significant_lines(schemas.MSG_TEXTS[f'conveyor_twin_msgs/srv/{name}_Request']) == \
        significant_lines(request)
