"""Cell description: YAML -> validated, frozen dataclasses in SI units."""

from conveyor_twin.cell.errors import CellError
from conveyor_twin.cell.loader import cell_from_mapping, default_cell_text, load_cell, load_cell_text
from conveyor_twin.cell.model import Cell

__all__ = ['Cell', 'CellError', 'cell_from_mapping', 'default_cell_text', 'load_cell',
           'load_cell_text']
