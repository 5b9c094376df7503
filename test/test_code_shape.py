"""The package's shape: no module over MAX_LINES lines, no function over MAX_PARAMETERS
parameters (``self`` and ``cls`` not counted), imports only down the layers of
docs/architecture.md and rclpy only in the layers that may use it."""

import ast
from pathlib import Path

import conveyor_twin

MAX_LINES = 600
MAX_PARAMETERS = 15
ROOT = Path(conveyor_twin.__file__).resolve().parent
#: The layers of docs/architecture.md, bottom up: a package imports only from lower rows.
LAYERS = (('contract', 'cell', 'wire', 'health', 'numba_cache'), ('micro', 'macro'), ('faults',),
          ('coupling',), ('coord',), ('output', 'plant'), ('record', 'split'), ('viz', 'plc'), ('ros',),
          ('testing',), ('cli', 'bench'))
#: The layers that may import rclpy and the ROS message packages.
ROS_LAYERS = ('ros', 'testing', 'cli', 'bench')
ROS_MODULES = ('rclpy', 'conveyor_twin_msgs', 'rosidl_runtime_py', 'rosgraph_msgs')


def _modules():
    return sorted(p for p in ROOT.rglob('*.py') if '__pycache__' not in p.parts)


def _name(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def parameter_count(node: ast.AST) -> int:
    """Return how many parameters a function takes, ``self`` and ``cls`` not counted."""
    args = node.args
    names = [a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    return len([n for n in names if n not in ('self', 'cls')])


def wide_functions(path: Path):
    """Yield (line, name, parameters) of the functions of ``path`` over MAX_PARAMETERS."""
    tree = ast.parse(path.read_text(encoding='utf-8'), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            count = parameter_count(node)
            if count > MAX_PARAMETERS:
                yield node.lineno, getattr(node, 'name', '<lambda>'), count


def test_the_checks_count_what_they_should(tmp_path):
    source = tmp_path / 'shape.py'
    wide = ', '.join(f'a{i}' for i in range(MAX_PARAMETERS))
    source.write_text(f'def fits(self, {wide}):\n    pass\n\n\n'
                      f'def wide(a, /, {wide}, *rest, k, **kw):\n    pass\n')
    assert list(wide_functions(source)) == [(5, 'wide', MAX_PARAMETERS + 4)]


def test_no_function_takes_more_than_the_most_parameters():
    wide = [f'{_name(p)}:{line} {name} takes {count} parameters'
            for p in _modules() for line, name, count in wide_functions(p)]
    assert wide == [], f'more than {MAX_PARAMETERS} parameters: {wide}'


def test_no_module_is_longer_than_the_most_lines():
    long = [f'{_name(p)}: {n} lines' for p in _modules()
            if (n := len(p.read_text(encoding='utf-8').splitlines())) > MAX_LINES
            ]
    assert long == [], f'modules over {MAX_LINES} lines: {long}'


def package_imports():
    """Yield (importing module, its package, imported module) of every absolute import."""
    for path in _modules():
        parts = path.relative_to(ROOT).parts
        package = parts[0].removesuffix('.py')
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names = [node.module]
            else:
                continue
            for name in names:
                yield _name(path), package, name


def test_imports_point_only_down_the_layers():
    row = {package: level for level, packages in enumerate(LAYERS) for package in packages}
    upward = []
    for module, package, name in package_imports():
        if package == '__init__' or not name.startswith('conveyor_twin.'):
            continue
        target = name.split('.')[1]
        if target != package and row[target] >= row[package]:
            upward.append(f'{module} imports {name}')
    assert upward == []


def test_every_package_has_a_layer():
    packages = {p.name.removesuffix('.py') for p in ROOT.iterdir()
                if (p.is_dir() and (p / '__init__.py').exists())
                or (p.suffix == '.py' and p.name != '__init__.py')}
    assert packages == {p for row in LAYERS for p in row}


def test_only_the_ros_layers_import_rclpy():
    below = [f'{module} imports {name}' for module, package, name in package_imports()
             if name.split('.')[0] in ROS_MODULES and package not in ROS_LAYERS]
    assert below == []
