"""Shared fixtures: where the real sample data lives (../shared/data beside the repo)."""
from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
LIDAR = SHARED_DATA / "lidar"


@pytest.fixture(scope="session")
def lidar_dir() -> Path:
    if not LIDAR.is_dir():
        pytest.fail(f"real sample data missing: {LIDAR} (../shared must sit beside the repo)")
    return LIDAR
