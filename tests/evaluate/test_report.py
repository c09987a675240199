import json
import math

import geopandas as gpd
import pytest
from shapely import LineString, box

from gisroads.evaluate import evaluate_network, format_report

UTM = "EPSG:32633"


def grid(offset=(0.0, 0.0), *, n=4, spacing=100.0, origin=(500000.0, 5000000.0)):
    """n x n crossing streets, spacing apart, each running 20 m past the outer ones."""
    x0, y0 = origin[0] + offset[0], origin[1] + offset[1]
    low, high = -20.0, (n - 1) * spacing + 20.0
    lines = [LineString([(x0 + low, y0 + k * spacing), (x0 + high, y0 + k * spacing)])
             for k in range(n)]
    lines += [LineString([(x0 + k * spacing, y0 + low), (x0 + k * spacing, y0 + high)])
              for k in range(n)]
    return gpd.GeoDataFrame(geometry=lines, crs=UTM)


def roads(lines, width_m=6.0):
    return gpd.GeoDataFrame(geometry=lines.buffer(width_m / 2, cap_style=2), crs=lines.crs)


def flat(results):
    return {f"{group}.{key}": value for group, values in results.items()
            for key, value in values.items()}


def test_results_are_plain_json_numbers():
    extracted, reference = grid((2.0, 0.0)), grid()
    results = evaluate_network(extracted, reference, extracted_polygons=roads(extracted),
                               reference_polygons=roads(reference))
    assert set(results) == {"buffer", "topology", "apls", "area"}
    values = flat(results)
    assert all(type(v) in (int, float) for v in values.values())
    assert json.loads(json.dumps(results)) == results
    assert values["buffer.completeness"] == pytest.approx(1.0, abs=1e-9)
    assert values["topology.junction_matches"] == 16
    assert values["area.spill_direction"] == 0.0


def test_area_group_needs_both_polygon_sets():
    results = evaluate_network(grid(), grid(), reference_polygons=roads(grid()))
    assert "area" not in results


def test_valid_area_applies_to_every_line_metric():
    # The extracted network is the reference west of x = 150 m and nothing east of it.
    reference = grid()
    valid = gpd.GeoSeries([box(500000 - 30, 5000000 - 30, 500150, 5000330)], crs=UTM)
    extracted = reference.clip(valid)
    results = evaluate_network(extracted, reference)
    assert results["buffer"]["completeness"] < 0.8
    assert results["topology"]["junction_recall"] == 0.5
    results = evaluate_network(extracted, reference, valid_area=valid)
    assert results["buffer"]["completeness"] == pytest.approx(1.0, abs=1e-9)
    assert results["apls"]["apls"] == pytest.approx(1.0, abs=1e-9)
    assert results["topology"]["junction_recall"] == 1.0


def test_geographic_reference_gives_the_utm_figures():
    extracted = grid((1.0, 2.0))
    extracted = gpd.GeoDataFrame(geometry=list(extracted.geometry[:-1]), crs=UTM)
    expected = flat(evaluate_network(extracted, grid()))
    got = flat(evaluate_network(extracted, grid().to_crs("EPSG:4326")))
    assert got.keys() == expected.keys()
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, rel=1e-6, abs=1e-9), key


def test_format_report():
    extracted, reference = grid((2.0, 0.0)), grid()
    results = evaluate_network(extracted, reference, extracted_polygons=roads(extracted),
                               reference_polygons=roads(reference))
    text = format_report(results)
    assert "completeness 100.0 %" in text
    assert f"RMS {results['buffer']['rms_m']:.2f} m" in text
    assert "16 matched within 10.00 m" in text
    assert text.splitlines()[-1].startswith("Area (0.50 m cells): precision")


def test_format_report_marks_undefined_values():
    results = evaluate_network(gpd.GeoSeries([], crs=UTM), grid())
    assert math.isnan(results["buffer"]["correctness"])
    assert "correctness n/a" in format_report(results)


def test_reference_junctions_replace_the_derived_ones():
    """A reference digitised with its junctions (fusa's has 7 where its lines share 3
    vertices) is scored on them; given in another CRS, clipped to the valid area."""
    from shapely import Point

    extracted, reference = grid((2.0, 0.0)), grid()
    crossings = [Point(500000.0 + 100 * i, 5000000.0 + 100 * j)
                 for i in range(4) for j in range(4)]
    given = gpd.GeoDataFrame(geometry=crossings[:10], crs=UTM).to_crs("EPSG:4326")
    derived = evaluate_network(extracted, reference)["topology"]
    scored = evaluate_network(extracted, reference, reference_junctions=given)["topology"]
    assert derived["junctions_reference"] == 16
    assert scored["junctions_reference"] == scored["junction_matches"] == 10
    assert scored["junction_recall"] == 1.0
    # the first ten crossings are columns i = 0, 1 and half of i = 2; keep x <= 500150
    area = gpd.GeoDataFrame(geometry=[box(499900, 4999900, 500150, 5000400)], crs=UTM)
    clipped = evaluate_network(extracted, reference, reference_junctions=given,
                               valid_area=area)["topology"]
    assert clipped["junctions_reference"] == 8


def test_the_spill_direction_reads_as_a_signed_share():
    extracted, reference = grid(), grid()
    results = evaluate_network(extracted, reference, extracted_polygons=roads(extracted, 8.0),
                               reference_polygons=roads(reference))
    assert results["area"]["spill_direction"] == 1.0
    assert "spill direction +1.00 (outward)" in format_report(results)
