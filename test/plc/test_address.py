"""Where a PLC server listens: ``[HOST:]PORT``, loopback unless told otherwise."""

import pytest

from conveyor_twin.plc.address import parse_address, PlcServerError


@pytest.mark.parametrize('text, expected', [
    ('4840', ('127.0.0.1', 4840)),
    (':502', ('127.0.0.1', 502)),
    ('0', ('127.0.0.1', 0)),
    ('0.0.0.0:5020', ('0.0.0.0', 5020)),
    ('localhost:65535', ('localhost', 65535)),
    ('[::1]:4840', ('::1', 4840)),
    (' 4841 ', ('127.0.0.1', 4841)),
])
def test_valid_addresses(text, expected) -> None:
    assert parse_address(text) == expected


@pytest.mark.parametrize('text, message', [
    ('65536', "'65536' is not an integer in \\[0, 65535\\]"),
    ('-1', "'-1' is not an integer"),
    ('host:', "port '' is not an integer"),
    ('opc.tcp://h:4840', 'not a URL'),
    ('::1:4840', 'IPv6 host in brackets'),
    ('[::1]', 'IPv6 host in brackets'),
    ('', "port '' is not an integer"),
])
def test_invalid_addresses_name_the_option_and_the_text(text, message) -> None:
    with pytest.raises(PlcServerError, match=message) as info:
        parse_address(text, option='--modbus')
    assert str(info.value).startswith(f'--modbus {text.strip()!r}')
    assert isinstance(info.value, ValueError)
