"""Same cell, seed and commands: identical bytes; another seed: different."""

from conveyor_twin.micro import MicroSim


def run(cell, seed, steps=3000):
    sim = MicroSim(cell, seed=seed)
    sim.step(1500)
    sim.set_belt_target(0, 0.8)
    sim.set_actuator_target(0, 0.3)
    for _ in range(steps - 1500):
        sim.step(1)
        sim.drain_events()
    return sim


def test_two_runs_identical_bytes(default_cell):
    a = run(default_cell, 3)
    b = run(default_cell, 3)
    assert a.n > 20
    assert a.state_bytes() == b.state_bytes()
    assert a.state_hash() == b.state_hash()
    c = run(default_cell, 4)
    assert c.state_hash() != a.state_hash()


def test_batched_steps_equal_single_steps(default_cell):
    a = MicroSim(default_cell, seed=1)
    b = MicroSim(default_cell, seed=1)
    a.step(800)
    for _ in range(800):
        b.step(1)
    assert a.state_bytes() == b.state_bytes()
