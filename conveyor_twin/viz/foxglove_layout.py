"""Foxglove layouts generated for a cell or a plant, naming exactly what its view serves.

A cell's layout (:func:`cell_layout`): a 3D panel with the ``scene`` and one density grid per
macro zone of the cell (``scene/density/ZONE``, coloured by ``density`` [parts/m²]), a plot of
every belt's actual and commanded speed, the state of every light barrier, the diagnostics and
a button publishing a command to the first belt. A plant's (:func:`plant_layout`): the same 3D
panel showing every cell's scene and grids in the plant frame, and a plot of the belt speeds of
every cell. ``conveyor-twin foxglove-layout CELL.yaml|PLANT.yaml -o layout.json`` writes one.
"""

import json
import re
from typing import Dict, List, Set

from conveyor_twin.cell.model import Belt, Cell
from conveyor_twin.contract import BELT_COMMAND, BELT_STATES, DIAGNOSTICS, LIGHT_BARRIERS
from conveyor_twin.record import topics as contract
from conveyor_twin.viz.foxglove_view import DENSITY_GRID_TOPIC, SCENE_TOPIC, density_zones

#: Colour range of the density grids [parts/m²].
DENSITY_RANGE = (0.0, 10000.0)


def _grid_settings() -> dict:
    return {'visible': True, 'colorField': 'density', 'colorMode': 'colormap',
            'colorMap': 'turbo', 'minValue': DENSITY_RANGE[0], 'maxValue': DENSITY_RANGE[1]}


def _scene_panel(topics: Dict[str, dict], frame: str, target_x: float) -> dict:
    return {'followMode': 'follow-none', 'followTf': frame, 'scene': {'enableStats': False},
            'cameraState': {'distance': max(4.5, 0.8 * target_x), 'perspective': True,
                            'phi': 50, 'thetaOffset': 90, 'targetOffset': [target_x, 0, 0],
                            'target': [0, 0, 0], 'targetOrientation': [0, 0, 0, 1],
                            'fovy': 45, 'near': 0.01, 'far': 5000},
            'topics': topics,
            'layers': {'grid': {'visible': True, 'layerId': 'foxglove.Grid', 'size': 20,
                                'divisions': 40, 'frameId': frame}}}


def _scene_topics(cell: Cell, namespace: str) -> Dict[str, dict]:
    topics = {contract.resolve(SCENE_TOPIC, namespace): {'visible': True}}
    for zone in density_zones(cell):
        topics[contract.resolve(f'{DENSITY_GRID_TOPIC}/{zone}', namespace)] = _grid_settings()
    return topics


def _belt_paths(cell: Cell, namespace: str, prefix: str = '') -> List[dict]:
    topic = contract.resolve(BELT_STATES.name, namespace)
    paths = []
    for i, belt in enumerate(cell.belts):
        for field, what in (('speed', 'speed'), ('commanded_speed', 'commanded')):
            paths.append({'value': f'{topic}.{field}[{i}]', 'enabled': True,
                          'timestampMethod': 'receiveTime',
                          'label': f'{prefix}{belt.name} {what}'})
    return paths


def _barrier_paths(cell: Cell, namespace: str, prefix: str = '') -> List[dict]:
    topic = contract.resolve(LIGHT_BARRIERS.name, namespace)
    return [{'value': f'{topic}.blocked[{i}]', 'timestampMethod': 'receiveTime',
             'label': f'{prefix}{barrier.name}'}
            for i, barrier in enumerate(cell.light_barriers)]


def _publish_panel(cell: Cell, namespace: str) -> dict:
    belt = cell.belts[0].name if cell.belts else ''
    return {'topicName': contract.resolve(BELT_COMMAND.name, namespace),
            'datatype': BELT_COMMAND.type_name, 'buttonText': 'Set belt speed',
            'value': json.dumps({'belt': belt, 'speed': 1.0}, indent=2)}


def _layout(config: dict, bottom: List[str]) -> dict:
    row: object = bottom[-1]
    for panel in reversed(bottom[:-1]):
        row = {'first': panel, 'second': row, 'direction': 'row'}
    return {'configById': config, 'globalVariables': {}, 'userNodes': {},
            'layout': {'first': '3D!scene', 'second': row, 'direction': 'column',
                       'splitPercentage': 62}}


def belt_x_max(belt: Belt) -> float:
    """Return the largest x [m] the camera should show of a belt: its end points' for a
    straight belt, its sector's for a curved one."""
    if belt.curve is None:
        return max(belt.start[0], belt.end[0])
    return max(x for x, _ in belt.outline())


def cell_layout(cell: Cell, namespace: str = '') -> dict:
    """Return the Foxglove layout (a JSON object) of the view of ``cell`` under ``namespace``."""
    extent = max((belt_x_max(b) for b in cell.belts), default=6.0)
    config = {
        '3D!scene': _scene_panel(_scene_topics(cell, namespace), cell.settings.frame_id,
                                 0.5 * extent),
        'Plot!belts': {'title': 'belt speeds [m/s]', 'paths': _belt_paths(cell, namespace),
                       'showLegend': True},
        'StateTransitions!barriers': {'paths': _barrier_paths(cell, namespace)},
        'DiagnosticSummary!diag': {'topicToRender': contract.resolve(DIAGNOSTICS.name, namespace),
                                   'sortByLevel': True},
    }
    bottom = ['Plot!belts', 'StateTransitions!barriers', 'DiagnosticSummary!diag']
    if cell.belts:
        config['Publish!belt'] = _publish_panel(cell, namespace)
        bottom.append('Publish!belt')
    return _layout(config, bottom)


def plant_layout(plant) -> dict:
    """Return the Foxglove layout of the view of a plant (``plant --foxglove``): every cell's
    scene and grids in the plant frame, every cell's belt speeds and light barriers."""
    from conveyor_twin.viz.foxglove_plant import plant_frame
    topics: Dict[str, dict] = {}
    belts: List[dict] = []
    barriers: List[dict] = []
    extent = 0.0
    for c in plant.cells:
        ns = '/' + c.namespace
        topics.update(_scene_topics(c.cell, ns))
        belts += _belt_paths(c.cell, ns, f'{c.name}: ')
        barriers += _barrier_paths(c.cell, ns, f'{c.name}: ')
        extent = max(extent, c.placement.x + max((belt_x_max(b) for b in c.cell.belts),
                                                 default=0.0))
    config = {
        '3D!scene': _scene_panel(topics, plant_frame(plant), 0.5 * extent),
        'Plot!belts': {'title': 'belt speeds [m/s]', 'paths': belts, 'showLegend': True},
        'StateTransitions!barriers': {'paths': barriers},
    }
    return _layout(config, ['Plot!belts', 'StateTransitions!barriers'])


_PATH_TOPIC = re.compile(r'^(/[^.\[]*)')


def layout_topics(layout: dict) -> Set[str]:
    """Every topic a layout reads (3D panel topics, message paths, diagnostics); the topics
    it publishes to are not included (see :func:`published_topics`)."""
    topics: Set[str] = set()
    for key, panel in layout['configById'].items():
        topics.update(panel.get('topics', {}))
        for path in panel.get('paths', ()):
            topics.add(_PATH_TOPIC.match(path['value']).group(1))
        if 'topicToRender' in panel:
            topics.add(panel['topicToRender'])
    return topics


def published_topics(layout: dict) -> Set[str]:
    """Topics a layout's panels publish to (each one a command topic of the view)."""
    return {panel['topicName'] for panel in layout['configById'].values()
            if 'topicName' in panel}
