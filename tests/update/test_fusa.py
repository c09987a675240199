"""The road database update on real data: fusa.laz through the LiDAR pipeline, compared with
its hand-digitised centre lines edited into databases with known changes (5 seeds).

Measured (bench/road_database_update.py, 10 seeds): fake roads flagged missing 1.0, deleted
roads found again 0.45. The issue's target for the latter (0.8) is not reached: the pipeline
finds about half of fusa's roads, and a deleted road the extraction misses cannot be new.
The floors below are the measured figures, so a regression fails.
"""
import geopandas as gpd
import pytest

from gisroads.lidar.pipeline import extract_roads
from gisroads.update import pooled_scores


@pytest.mark.slow
def test_fusa_lidar_against_its_edited_truth(lidar_dir):
    extracted = extract_roads(lidar_dir / "fusa.laz").network.centrelines
    truth = gpd.read_file(lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson")
    # a 250 m tile: fake roads 20-40 m long, 15 m clear of the digitised roads
    scores = pooled_scores(extracted, truth, range(5), fake_length_m=(20.0, 40.0),
                           fake_clearance_m=15.0)
    assert scores["missing"]["actual"] == 5 and scores["new"]["actual"] == 10
    assert scores["missing"]["recall"] >= 0.9  # fake roads flagged missing
    assert scores["new"]["recall"] >= 0.4  # deleted roads found again
    assert scores["new"]["precision"] >= 0.9
