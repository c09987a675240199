"""What the tests of tiled runs share: the CLI command, its environment, and geometry
equality."""
import os
import sys
from pathlib import Path

import numpy as np
import shapely

GISROADS = [sys.executable, "-m", "gisroads.cli"]
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(Path(__file__).parents[2])}


def assert_same_geometries(a, b):
    """Two layers hold the same geometries, in the same order, to the bit."""
    assert len(a) == len(b)
    assert np.array_equal(shapely.to_wkb(a.geometry.values), shapely.to_wkb(b.geometry.values))
