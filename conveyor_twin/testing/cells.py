"""Cells for tests: the default cell as it ships, and variants of it."""

import yaml

from conveyor_twin.cell import cell_from_mapping, default_cell_text
from conveyor_twin.cell.model import Cell


def quiet_cell() -> Cell:
    """Return the default cell without its feeder: only the parts a test spawns move."""
    doc = yaml.safe_load(default_cell_text())
    doc['sources'] = []
    return cell_from_mapping(doc, 'default cell without sources')
