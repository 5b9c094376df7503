"""The ``conveyor-twin`` command: a dictionary of verbs, each a module with ``main(argv)``."""

import importlib
import sys
from typing import List, Optional

from conveyor_twin import __version__

# verb -> (module, one-line help). Each module has ``main(argv: List[str]) -> int``.
VERBS = {
    'run': ('conveyor_twin.cli.run', 'run the twin on a cell (default: the embedded cell)'),
    'plant': ('conveyor_twin.cli.plant',
              'run a plant of cells coupled by transfer links (one process per cell)'),
    'validate': ('conveyor_twin.cli.validate', 'check a cell file and summarise it'),
    'bench': ('conveyor_twin.cli.bench', 'run a benchmark: micro, macro, twin, scale'),
    'record': ('conveyor_twin.cli.record', "record a live twin's topics to MCAP"),
    'replay': ('conveyor_twin.cli.replay', 'republish a recording with its original timing'),
    'info': ('conveyor_twin.cli.info', 'summarize a recording (topics, counts, rates)'),
    'recover': ('conveyor_twin.cli.recover', 'rebuild a killed or damaged recording'),
    'plot': ('conveyor_twin.cli.plot',
             "draw a cell's layout (CELL.yaml) or a recording's figures (RUN.mcap)"),
    'animate': ('conveyor_twin.cli.animate',
                'render a recording as a GIF or MP4 (parts, density, barriers, belts)'),
    'resimulate': ('conveyor_twin.cli.resimulate',
                   're-run a recording and compare every message bit for bit'),
    'plc-map': ('conveyor_twin.cli.plc_map',
                "print a cell's PLC tags: OPC UA paths, Modbus addresses (CSV or Markdown)"),
    'warm-up': ('conveyor_twin.cli.warm_up',
                'compile or load the simulation kernels ahead (make setup runs it)'),
    'foxglove-layout': ('conveyor_twin.cli.foxglove_layout',
                        "write the Foxglove layout of a cell's (or a plant's) live view"),
}


def _usage() -> str:
    lines = ['usage: conveyor-twin [--version] VERB [options]', '', 'verbs:']
    width = max(len(verb) for verb in VERBS) + 2
    lines += [f'  {verb:<{width}}{help_}' for verb, (_, help_) in VERBS.items()]
    lines += ['', "'conveyor-twin VERB --help' describes a verb."]
    return '\n'.join(lines)


def main(argv: Optional[List[str]] = None) -> int:
    """Dispatch ``conveyor-twin VERB ...`` to the verb's module; return the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ('-h', '--help'):
        print(_usage())
        return 0 if argv else 2
    verb = argv[0]
    if verb in ('-V', '--version'):
        print(f'conveyor-twin {__version__}')
        return 0
    if verb not in VERBS:
        print(f'conveyor-twin: unknown verb {verb!r}\n\n{_usage()}', file=sys.stderr)
        return 2
    module = importlib.import_module(VERBS[verb][0])
    return int(module.main(argv[1:]) or 0)


if __name__ == '__main__':
    sys.exit(main())
