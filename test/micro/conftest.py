"""Cells for the micro tests, built from the default cell with dataclasses.replace."""

from dataclasses import replace

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Belt, Obstacle, PartType


def disc(radius=0.005, mass=0.01, restitution=0.5, mu_s=0.0, mu_k=0.0, height=0.01,
         name='disc'):
    """Return a disc part type (inertia m r^2 / 2)."""
    return PartType(name=name, shape='disc', radius=radius, length=0.0, width=0.0,
                    height=height, mass=mass, inertia=0.5 * mass * radius ** 2,
                    restitution=restitution, friction_static=mu_s, friction_sliding=mu_k,
                    friction_transition_speed=0.01)


def box(length=0.02, width=0.01, mass=0.01, name='box'):
    """Return a box part type (inertia m (l^2 + w^2) / 12)."""
    return PartType(name=name, shape='box', radius=0.0, length=length, width=width,
                    height=0.01, mass=mass, inertia=mass * (length ** 2 + width ** 2) / 12,
                    restitution=0.3, friction_static=0.3, friction_sliding=0.2,
                    friction_transition_speed=0.01)


def make_cell(*, part_types=None, obstacles=(), speed=0.0, friction=0.35, length=2.0,
              width=0.5, sources=(), sinks=(), light_barriers=(), actuators=(), **micro):
    """Return a one-belt cell along +x from (0, 0) with the given contents."""
    base = load_cell(None)
    belt = Belt(name='belt', start=(0.0, 0.0), end=(length, 0.0), width=width, speed=speed,
                max_speed=2.0, acceleration=2.0, friction=friction)
    return replace(base, belts=(belt,), obstacles=tuple(obstacles),
                   part_types=tuple(part_types or (disc(),)), sources=tuple(sources),
                   sinks=tuple(sinks), light_barriers=tuple(light_barriers),
                   actuators=tuple(actuators), zones=(),
                   micro=replace(base.micro, capacity=micro.pop('capacity', 256), **micro))


def wall(name, a, b, thickness=0.0, restitution=0.3, friction=0.2, kind='wall'):
    """Return a wall obstacle from a to b."""
    return Obstacle(name=name, kind=kind, points=(a, b), thickness=thickness,
                    restitution=restitution, friction=friction)


@pytest.fixture(scope='session')
def default_cell():
    """The embedded default cell."""
    return load_cell(None)
