"""The ``.msg`` texts a recording stores as schemas, read from the message definition files.

The ``conveyor_twin_msgs`` types are read from the interface package's own files,
``msg_defs/msg/*.msg`` and (the requests the recorder stores) ``msg_defs/srv/*.srv``: in the
source tree (``pip install -e``, ``colcon build --symlink-install``) from ``msg_defs/`` next to
the ``conveyor_twin`` package; in an installed package (wheel, ``colcon build``) from the copy
the build puts into ``conveyor_twin/wire/msg/conveyor_twin_msgs/`` (``setup.py``). The types
of other ROS packages the twin records (std, builtin, rosgraph, diagnostic, geometry, sensor,
visualization messages) are ``conveyor_twin/wire/msg/<package>/msg/<Type>.msg``, as the Kilted
packages ship them, so a recording's schemas do not depend on the installed distro.
"""

from pathlib import Path
from typing import Dict, Tuple

#: Interface package of the contract.
CONTRACT_PACKAGE = 'conveyor_twin_msgs'
#: ``<package>/msg/<Type>.msg`` of the recorded types of other packages, and (installed) the
#: copy of ``msg_defs/`` as ``conveyor_twin_msgs/{msg,srv}/``.
MSG_DIR = Path(__file__).resolve().parent / 'msg'
#: The interface package's sources in the source tree.
SOURCE_MSG_DEFS = Path(__file__).resolve().parents[2] / 'msg_defs'
#: Services whose requests a recording stores (the accepted ``spawn_parts`` and ``reset``).
RECORDED_REQUESTS: Tuple[str, ...] = ('SpawnParts', 'Reset')


def contract_dir() -> Path:
    """Return the directory holding ``msg/`` and ``srv/`` of ``conveyor_twin_msgs``.

    :raises FileNotFoundError: naming both places looked in, when neither has ``msg/``.
    """
    for candidate in (MSG_DIR / CONTRACT_PACKAGE, SOURCE_MSG_DEFS):
        if (candidate / 'msg').is_dir():
            return candidate
    raise FileNotFoundError(
        f'the {CONTRACT_PACKAGE} message definitions are missing: neither '
        f'{MSG_DIR / CONTRACT_PACKAGE}/msg (an installed conveyor_twin) nor '
        f'{SOURCE_MSG_DEFS}/msg (the source tree) exists; reinstall conveyor_twin')


def request_text(srv_text: str) -> str:
    """Return the text of a service's request as recorded: the part of the ``.srv`` text before
    its ``---`` line, without the comment paragraph at its top (the service's description)."""
    lines = srv_text.splitlines(keepends=True)
    end = next((i for i, line in enumerate(lines) if line.rstrip('\r\n') == '---'), len(lines))
    start = 0
    while start < end and (lines[start].startswith('#') or not lines[start].strip()):
        start += 1
    return ''.join(lines[start:end])


def read_texts() -> Dict[str, str]:
    """Return the ``.msg`` text of every known type by full type name (``pkg/msg/Type``; the
    recorded service requests as ``conveyor_twin_msgs/srv/<Service>_Request``).

    :raises FileNotFoundError: if a definition directory or file is missing (naming it).
    """
    contract = contract_dir()
    texts: Dict[str, str] = {}
    for path in sorted((contract / 'msg').glob('*.msg')):
        texts[f'{CONTRACT_PACKAGE}/msg/{path.stem}'] = _read(path)
    for service in RECORDED_REQUESTS:
        path = contract / 'srv' / f'{service}.srv'
        texts[f'{CONTRACT_PACKAGE}/srv/{service}_Request'] = request_text(_read(path))
    others = sorted(MSG_DIR.glob('*/msg/*.msg'))
    if not others:
        raise FileNotFoundError(f'no message definitions in {MSG_DIR}/<package>/msg/; '
                                'reinstall conveyor_twin')
    for path in others:
        package = path.parent.parent.name
        if package != CONTRACT_PACKAGE:
            texts[f'{package}/msg/{path.stem}'] = _read(path)
    return texts


def _read(path: Path) -> str:
    try:
        return path.read_bytes().decode('utf-8')
    except FileNotFoundError:
        raise FileNotFoundError(f'message definition {path} is missing') from None
