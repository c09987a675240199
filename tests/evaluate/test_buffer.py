import math

import geopandas as gpd
import numpy as np
import pytest
import shapely
from shapely import LineString, box

from gisroads.evaluate import buffer_metrics, match_layers

REFERENCE = [LineString([(0, 0), (100, 0)])]
UTM = "EPSG:32633"


def grid(offset=(0.0, 0.0), *, n=4, spacing=100.0, origin=(500000.0, 5000000.0)):
    """n horizontal and n vertical lines, each (n - 1) * spacing long, shifted by offset."""
    x0, y0 = origin[0] + offset[0], origin[1] + offset[1]
    span = (n - 1) * spacing
    lines = [LineString([(x0, y0 + k * spacing), (x0 + span, y0 + k * spacing)])
             for k in range(n)]
    lines += [LineString([(x0 + k * spacing, y0), (x0 + k * spacing, y0 + span)])
              for k in range(n)]
    return gpd.GeoDataFrame(geometry=lines, crs=UTM)


def test_parallel_offset_within_buffer_matches_everything():
    # Every point of each line is 2 m from the other, inside the 3 m buffer.
    m = buffer_metrics([LineString([(0, 2), (100, 2)])], REFERENCE, buffer_m=3.0)
    assert m.completeness == pytest.approx(1.0, abs=1e-9)
    assert m.correctness == pytest.approx(1.0, abs=1e-9)
    assert m.quality == pytest.approx(1.0, abs=1e-9)
    assert m.rms_m == pytest.approx(2.0, abs=1e-9)
    assert m.extracted_length_m == pytest.approx(100.0, abs=1e-9)
    assert m.reference_length_m == pytest.approx(100.0, abs=1e-9)


def test_half_overlap_counts_the_round_cap():
    # Extracted x = 50..150 on the reference's axis. The round cap of the reference's buffer
    # reaches x = 103, so the extracted part x = 50..103 (53 m) is matched; symmetrically the
    # extracted buffer starts at x = 47, matching reference x = 47..100 (53 m).
    # quality = 53 / (100 extracted + 47 unmatched reference) = 53 / 147.
    # RMS: the matched 53 m is cut into 106 parts of 0.5 m; midpoints x = 100.25 .. 102.75 are
    # 0.25, 0.75, ..., 2.75 m from the reference's end, the others 0 m:
    # sum of squares 17.875, RMS = sqrt(0.5 * 17.875 / 53).
    m = buffer_metrics([LineString([(50, 0), (150, 0)])], REFERENCE, buffer_m=3.0)
    assert m.completeness == pytest.approx(0.53, abs=1e-9)
    assert m.correctness == pytest.approx(0.53, abs=1e-9)
    assert m.quality == pytest.approx(53 / 147, abs=1e-9)
    assert m.matched_extracted_m == pytest.approx(53.0, abs=1e-9)
    assert m.matched_reference_m == pytest.approx(53.0, abs=1e-9)
    assert m.rms_m == pytest.approx(math.sqrt(0.5 * 17.875 / 53), abs=1e-9)


def test_offset_beyond_buffer_matches_nothing():
    m = buffer_metrics([LineString([(0, 5), (100, 5)])], REFERENCE, buffer_m=3.0)
    assert (m.completeness, m.correctness, m.quality) == (0.0, 0.0, 0.0)
    assert math.isnan(m.rms_m)


def test_quality_combines_false_positives_and_false_negatives():
    # A 60 m hit on the axis plus a 40 m false positive 20 m away: matched extracted 60 of 100;
    # the hit's cap reaches x = 63, so 63 m of reference matched and 37 m missed.
    # quality = 60 / (100 + 37).
    extracted = [LineString([(0, 0), (60, 0)]), LineString([(0, 20), (40, 20)])]
    m = buffer_metrics(extracted, REFERENCE, buffer_m=3.0)
    assert m.correctness == pytest.approx(0.6, abs=1e-9)
    assert m.completeness == pytest.approx(0.63, abs=1e-9)
    assert m.quality == pytest.approx(60 / 137, abs=1e-9)
    assert m.rms_m == pytest.approx(0.0, abs=1e-9)


def test_valid_area_clips_both_networks():
    # Valid x = 0..80: the reference is 80 m; the extracted 50 m hit stays, the line at y = 30
    # is outside. Matched reference x = 0..53 (cap); quality = 50 / (50 + 27).
    extracted = [LineString([(0, 0), (50, 0)]), LineString([(0, 30), (100, 30)])]
    m = buffer_metrics(extracted, REFERENCE, buffer_m=3.0, valid_area=box(0, -10, 80, 10))
    assert m.reference_length_m == pytest.approx(80.0, abs=1e-9)
    assert m.extracted_length_m == pytest.approx(50.0, abs=1e-9)
    assert m.completeness == pytest.approx(53 / 80, abs=1e-9)
    assert m.correctness == pytest.approx(1.0, abs=1e-9)
    assert m.quality == pytest.approx(50 / 77, abs=1e-9)


def test_duplicated_extracted_lines_count_once():
    twice = [LineString([(0, 2), (100, 2)])] * 2
    assert buffer_metrics(twice, REFERENCE).extracted_length_m == pytest.approx(100.0)


def test_empty_extracted_scores_zero_and_nan():
    m = buffer_metrics(gpd.GeoSeries([], crs=UTM), REFERENCE)
    assert m.completeness == 0.0 and m.quality == 0.0
    assert math.isnan(m.correctness) and math.isnan(m.rms_m)


def test_empty_reference_raises():
    with pytest.raises(ValueError, match="reference"):
        buffer_metrics(REFERENCE, gpd.GeoSeries([], crs=UTM))


def test_polygons_are_refused():
    with pytest.raises(ValueError, match="Polygon"):
        buffer_metrics([box(0, 0, 1, 1)], REFERENCE)


def test_network_against_itself_is_perfect():
    m = buffer_metrics(grid(), grid())
    assert (m.completeness, m.correctness, m.quality) == pytest.approx((1, 1, 1), abs=1e-9)
    assert m.rms_m == pytest.approx(0.0, abs=1e-9)


def test_network_shifted_5m_scores_low():
    # Shifted 5 m diagonally, every line is 3.54 m from its twin: only the stretches near the
    # crossings with perpendicular lines fall inside the 3 m buffer.
    m = buffer_metrics(grid((5 / math.sqrt(2), 5 / math.sqrt(2))), grid(), buffer_m=3.0)
    assert 0 < m.completeness < 0.2
    assert 0 < m.correctness < 0.2
    assert 0 < m.quality < 0.2


def test_geographic_reference_gives_the_utm_figures():
    extracted = grid((1.0, 2.0))
    expected = buffer_metrics(extracted, grid()).as_dict()
    got = buffer_metrics(extracted, grid().to_crs("EPSG:4326")).as_dict()
    assert got == pytest.approx(expected, rel=1e-6)


def test_missing_crs_is_assumed_shared():
    extracted = grid((1.0, 2.0))
    expected = buffer_metrics(extracted, grid()).as_dict()
    got = buffer_metrics(np.asarray(extracted.geometry.values), grid()).as_dict()
    assert got == pytest.approx(expected, rel=1e-12)


def test_match_layers_label_pieces():
    layers = match_layers(gpd.GeoSeries([LineString([(50, 0), (150, 0)])], crs=UTM),
                          gpd.GeoSeries(REFERENCE, crs=UTM), buffer_m=3.0)
    extracted, reference = layers["eval_extracted"], layers["eval_reference"]
    assert extracted.crs == reference.crs == UTM
    lengths = extracted.groupby("status")["length_m"].sum().to_dict()
    assert lengths == pytest.approx({"TP": 53.0, "FP": 47.0})
    lengths = reference.groupby("status")["length_m"].sum().to_dict()
    assert lengths == pytest.approx({"TP": 53.0, "FN": 47.0})
    assert shapely.equals(reference.geometry[reference["status"] == "FN"].iloc[0],
                          LineString([(0, 0), (47, 0)]))
