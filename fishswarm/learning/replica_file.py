"""Learned replica files (``best_replica.npz``): what a swarm needs to run a learned replica.

Kept apart from the learning session so that running a replica needs only the core
dependencies (no CMA-ES).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.learning.networks import REPLICA_SIZE

FloatArray = NDArray[np.float64]


class ReplicaFileError(ValueError):
    """A file is not a learned replica; the message says why."""


def load_replica(path: Path) -> tuple[FloatArray, dict[str, Any]]:
    """Read ``best_replica.npz``: the weights (21,) and the settings they were learned with.

    Raises:
        ReplicaFileError: the file is missing or not a replica.
    """
    try:
        # Opened here, so that a file numpy refuses is still closed.
        with path.open("rb") as stream, np.load(stream, allow_pickle=False) as data:
            weights = np.asarray(data["weights"], dtype=np.float64)
            settings = json.loads(str(data["settings"]))
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        raise ReplicaFileError(
            f"{path} is not a learned replica (expected a best_replica.npz written by "
            "'fishswarm learn')"
        ) from None
    if weights.shape != (REPLICA_SIZE,) or not np.all(np.isfinite(weights)):
        raise ReplicaFileError(
            f"{path} holds weights of shape {weights.shape}, not ({REPLICA_SIZE},)"
        )
    return weights, settings
