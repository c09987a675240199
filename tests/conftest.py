"""Shared fixtures: where the real sample data lives (../shared/data beside the repo)."""
from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
LIDAR = SHARED_DATA / "lidar"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"real sample data missing: {SHARED_DATA} (../shared must sit beside the "
                    "repo)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def lidar_dir() -> Path:
    if not LIDAR.is_dir():
        pytest.fail(f"real sample data missing: {LIDAR} (../shared must sit beside the repo)")
    return LIDAR
