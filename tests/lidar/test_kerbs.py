"""The evidence cue's kerbs: ground steps found on a kerb and not on a slope or a camber, a
raised median cut between two carriageways and nothing cut on a plain street or a short
notch, and fusa's divided road drawn as its two carriageways."""
import numpy as np
import pytest

from gisroads.lidar.evidence import KERB_GRADIENT, kerb_steps, median_cells

CELL = 0.5


def test_kerb_steps_find_a_kerb_and_not_a_slope_or_a_camber():
    rng = np.random.default_rng(0)
    x = np.arange(120) * CELL  # metres across, 60 m
    y = np.arange(80)[:, None] * CELL
    # a 6 % slope along y, a 2 % camber over an 8 m carriageway from x = 20 m to 28 m, the
    # sidewalk beyond its east kerb (x = 28 m) 15 cm up; ranging noise 2 cm
    camber = np.where((x >= 20) & (x < 28), 0.02 * (4 - np.abs(x - 24)), 0.0)
    ground = 0.06 * y + camber + np.where(x >= 28, 0.15, 0.0)
    ground = ground + rng.normal(0, 0.02, ground.shape)
    ground[rng.random(ground.shape) < 0.2] = np.nan  # scan gaps
    steps = kerb_steps(ground, CELL)
    inner = slice(10, 70)
    # a clean 15 cm step peaks at 0.076
    at_kerb = steps[inner, 55:57].max(axis=1)
    assert (at_kerb >= KERB_GRADIENT).mean() > 0.9
    # the carriageway's crown and the slope stay under it; the data's edge has no value
    assert np.nanmax(steps[inner, 42:52]) < KERB_GRADIENT
    assert np.nanmax(steps[inner, 70:110]) < KERB_GRADIENT
    holes = np.isnan(kerb_steps(np.full((40, 40), np.nan), CELL))
    assert holes.all()


def divided_road():
    """Cells of 0.5 m: two 6 m carriageways along the rows, a 2.5 m raised median between them
    over rows 0-59 (paved, as a concrete median is; kerb cells along both its sides), one
    14.5 m carriageway beyond its nose; sidewalks 2 m wide beyond the outer kerbs."""
    paved = np.zeros((120, 60), bool)
    kerb = np.zeros_like(paved)
    paved[:, 5:44] = True
    kerb[:, 9] = kerb[:, 39] = True  # outer kerbs: carriageways from column 10 to 38
    kerb[:60, 21] = kerb[:60, 27] = True  # the median's kerbs; the median is 22-26
    return paved, kerb


def test_a_raised_median_is_cut_and_a_plain_street_or_a_notch_is_not():
    paved, kerb = divided_road()
    cut = median_cells(paved, kerb, CELL)
    # the median and its kerbs, between the carriageways, along the median
    rows, cols = np.nonzero(cut)
    assert cols.min() >= 21 and cols.max() <= 27
    assert cut[5:55, 21:28].mean() > 0.9
    assert not cut[:, :21].any() and not cut[:, 28:].any()
    # a street with kerbs along both edges and sidewalks beyond: nothing
    street = np.zeros((120, 60), bool)
    street[:, 5:31] = True
    street_kerb = np.zeros_like(street)
    street_kerb[:, 9] = street_kerb[:, 26] = True
    assert not median_cells(street, street_kerb, CELL).any()
    # a notch shorter than a car in a carriageway's edge is no median
    notch = street.copy()
    notch[50:56, 10:13] = False
    notch_kerb = street_kerb.copy()
    notch_kerb[50:56, 13] = True
    assert not median_cells(notch, notch_kerb, CELL).any()


@pytest.mark.slow
def test_fusa_divided_road_is_drawn_as_its_two_carriageways(lidar_dir):
    import shapely

    from gisroads.lidar.pipeline import extract_roads

    roads = extract_roads(lidar_dir / "fusa.laz", cue="evidence").network.centrelines
    assert "kerbs" in roads["cues"].iloc[0].split(",")
    # across SER's divided end at y = 6122345, where the digitised SER_W_divided and
    # SER_E_divided run at x = 277986 and 277994 (6 m carriageways, a raised median between):
    # measured 277985.5 and 277992.7; without the kerbs cue one line between, at 277989.4
    section = shapely.LineString([(277970, 6122345), (278000, 6122345)])
    crossing = shapely.get_coordinates(shapely.intersection(
        shapely.union_all(roads.to_crs(32754).geometry.values), section))[:, 0]
    assert len(crossing) == 2
    assert abs(crossing.min() - 277986) < 2.0 and abs(crossing.max() - 277994) < 2.0
