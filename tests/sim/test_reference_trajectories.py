"""Seeded runs give the trajectories recorded before the fish core and package refactor.

``tests/sim/data/reference_trajectories.npz`` holds the batch engine's trajectories of every
behaviour, both controllers, the jitter mode and the first and last setting of each study
experiment, recorded at commit 842bbda (rewritten on an AVX-512 machine once they agreed to
4e-8). Refactors must leave them bit for bit; a change that is meant to move them (a new
model) regenerates the file on purpose:
``python -m tests.sim.test_reference_trajectories --write``.

Bit for bit holds under the numpy release and the CPU's SIMD level the file was written with
(stored in it as ``platform``): another release, or the same release dispatching to other
vector instructions (AVX-512 rather than AVX2), may round its vectorised ``sin``/``exp``
differently in the last place, which moves trajectories by about 1e-16 m a tick (4e-8 rad
after 120 s of milling, measured between an AVX2 and an AVX-512 machine). On another
platform the runs must agree to ``TOLERANCE`` instead, and the neighbour counts exactly.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).resolve().parent / "data" / "reference_trajectories.npz"
TOLERANCE = 1e-6  # m, m/s and rad
REPLICA_WEIGHTS = np.linspace(-2.0, 2.0, 21) * np.cos(np.arange(21.0))


def _cases(model: Path) -> dict[str, dict[str, object]]:
    """Scenario settings of each reference run, by name."""
    cases: dict[str, dict[str, object]] = {}
    for behavior in ("dispersion", "aggregation", "orbit", "milling", "waltz"):
        cases[f"run-{behavior}"] = {"behavior": behavior, "seed": 1}
    cases["run-replica"] = {"behavior": "replica", "seed": 1, "model": str(model)}
    cases["run-aggregation-pid"] = {"behavior": "aggregation", "controller": "pid", "seed": 2}
    cases["run-milling-pid"] = {"behavior": "milling", "controller": "pid", "seed": 2}
    cases["run-dispersion-jitter-noise"] = {
        "behavior": "dispersion",
        "time_mode": "jitter",
        "vision_noise": 0.05,
        "seed": 3,
    }
    cases["run-orbit-jitter"] = {"behavior": "orbit", "time_mode": "jitter", "seed": 3}
    return cases


def _experiment_cases() -> dict[str, tuple[str, str]]:
    return {
        f"experiment-{name}-{which}": (name, which)
        for name in ("blindspot", "blockingsphere", "orbit", "milling", "waltz")
        for which in ("first", "last")
    }


def compute(model: Path) -> dict[str, np.ndarray]:
    """Every reference run's positions, velocities and yaws, as named arrays."""
    from fishswarm.sim.engine import simulate_batch
    from fishswarm.sim.scenario import Scenario
    from fishswarm.study.experiment import find

    scenarios: dict[str, Scenario] = {
        name: Scenario().replace(**settings) for name, settings in _cases(model).items()
    }
    for name, (experiment_name, which) in _experiment_cases().items():
        experiment = find(experiment_name)
        value = experiment.values[0] if which == "first" else experiment.values[-1]
        scenarios[name] = experiment.scenario_for(value, 0)
    arrays: dict[str, np.ndarray] = {}
    for name, scenario in scenarios.items():
        trajectory = simulate_batch(scenario)
        arrays[f"{name}/position"] = trajectory.position
        arrays[f"{name}/velocity"] = trajectory.velocity
        arrays[f"{name}/yaw"] = trajectory.yaw
        arrays[f"{name}/seen"] = trajectory.neighbors_seen
    return arrays


def write_model(path: Path) -> Path:
    """A fixed replica network (not learned: any weights exercise the behaviour)."""
    np.savez(path, weights=REPLICA_WEIGHTS, settings='{"behavior": "aggregation"}')
    return path


@pytest.fixture(scope="module")
def computed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    return compute(write_model(tmp_path_factory.mktemp("model") / "replica.npz"))


def platform() -> str:
    """The numpy release and the SIMD targets it dispatches to on this CPU."""
    umath = importlib.import_module("numpy._core._multiarray_umath")
    features: dict[str, bool] = getattr(umath, "__cpu_features__", {})
    targets = [name for name in getattr(umath, "__cpu_dispatch__", []) if features.get(name)]
    return f"numpy {np.__version__} on {' '.join(targets) or 'baseline'}"


_NOT_TRAJECTORIES = ("numpy_version", "platform")


@pytest.fixture(scope="module")
def reference() -> dict[str, np.ndarray]:
    with np.load(DATA) as data:
        return {name: data[name] for name in data.files if name not in _NOT_TRAJECTORIES}


@pytest.fixture(scope="module")
def recorded_on_this_platform() -> bool:
    with np.load(DATA) as data:
        return "platform" in data.files and str(data["platform"]) == platform()


def test_every_reference_run_is_recomputed(
    computed: dict[str, np.ndarray], reference: dict[str, np.ndarray]
) -> None:
    assert sorted(computed) == sorted(reference)
    assert len(reference) == 4 * (len(_cases(Path("m"))) + len(_experiment_cases()))


def test_trajectories_are_bit_identical_to_the_reference(
    computed: dict[str, np.ndarray],
    reference: dict[str, np.ndarray],
    recorded_on_this_platform: bool,
) -> None:
    def same(name: str) -> bool:
        if recorded_on_this_platform or name.endswith("/seen"):
            return np.array_equal(computed[name], reference[name])
        return np.allclose(computed[name], reference[name], rtol=0.0, atol=TOLERANCE)

    differing = [name for name in reference if not same(name)]
    assert not differing, f"trajectories changed: {differing}"
    # The runs move: a reference of fish at rest would prove nothing.
    assert np.ptp(reference["run-dispersion/position"][:, :, 0]) > 0.5


if __name__ == "__main__" and "--write" in sys.argv:
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        result = compute(write_model(Path(folder) / "replica.npz"))
    DATA.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(DATA, platform=np.array(platform()), **result)  # type: ignore[arg-type]
    print(f"wrote {len(result)} arrays to {DATA}")
