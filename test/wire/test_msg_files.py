"""The .msg texts come from the definition files: msg_defs/ (source tree or installed copy) and
the standard types' files in conveyor_twin/wire/msg/."""

from pathlib import Path

import pytest

from conveyor_twin.wire import msg_files, schemas

ROOT = Path(__file__).resolve().parents[2]
MSG_DEFS = ROOT / 'msg_defs'


def test_contract_texts_are_msg_defs_byte_for_byte():
    for path in sorted((MSG_DEFS / 'msg').glob('*.msg')):
        assert schemas.MSG_TEXTS[f'conveyor_twin_msgs/msg/{path.stem}'].encode() == \
            path.read_bytes(), path.name


@pytest.mark.parametrize('service', msg_files.RECORDED_REQUESTS)
def test_recorded_request_is_the_request_part_without_its_description(service):
    srv = (MSG_DEFS / 'srv' / f'{service}.srv').read_text()
    text = schemas.MSG_TEXTS[f'conveyor_twin_msgs/srv/{service}_Request']
    assert '---' not in text and not text.startswith(('#', '\n'))
    assert text.endswith('\n') and srv.startswith('# ')
    assert srv.split('\n---\n')[0] + '\n' == srv[:srv.index(text)] + text


def test_request_text_keeps_comments_after_the_first_field():
    srv = '# What it does.\n#\n\nstring a  # the a\n# about b\nuint8 b\n---\nbool ok\n'
    assert msg_files.request_text(srv) == 'string a  # the a\n# about b\nuint8 b\n'
    assert msg_files.request_text('---\nbool ok\n') == ''


def test_standard_texts_are_files_of_the_package():
    others = {name for name in schemas.MSG_TEXTS if not name.startswith('conveyor_twin_msgs/')}
    files = {f'{p.parent.parent.name}/msg/{p.stem}'
             for p in msg_files.MSG_DIR.glob('*/msg/*.msg')}
    assert others == files and 'std_msgs/msg/Header' in others


def test_installed_copy_is_preferred(tmp_path, monkeypatch):
    installed = tmp_path / 'msg' / 'conveyor_twin_msgs'
    (installed / 'msg').mkdir(parents=True)
    monkeypatch.setattr(msg_files, 'MSG_DIR', tmp_path / 'msg')
    assert msg_files.contract_dir() == installed
    monkeypatch.setattr(msg_files, 'MSG_DIR', tmp_path / 'elsewhere')
    assert msg_files.contract_dir() == msg_files.SOURCE_MSG_DEFS


def test_missing_definitions_name_both_places(tmp_path, monkeypatch):
    monkeypatch.setattr(msg_files, 'MSG_DIR', tmp_path / 'msg')
    monkeypatch.setattr(msg_files, 'SOURCE_MSG_DEFS', tmp_path / 'msg_defs')
    with pytest.raises(FileNotFoundError) as err:
        msg_files.read_texts()
    assert str(tmp_path / 'msg' / 'conveyor_twin_msgs') in str(err.value)
    assert str(tmp_path / 'msg_defs') in str(err.value)


def test_missing_file_is_named(tmp_path, monkeypatch):
    (tmp_path / 'msg_defs' / 'msg').mkdir(parents=True)
    monkeypatch.setattr(msg_files, 'MSG_DIR', tmp_path / 'msg')
    monkeypatch.setattr(msg_files, 'SOURCE_MSG_DEFS', tmp_path / 'msg_defs')
    with pytest.raises(FileNotFoundError, match='SpawnParts.srv is missing'):
        msg_files.read_texts()
