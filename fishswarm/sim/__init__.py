"""The simulated world as pure functions: scenario, placement, one tick, perception, medium."""
