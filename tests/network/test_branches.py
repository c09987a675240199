"""Branches of a network that lead only into an area: a car park's entrance and drives."""
import numpy as np
from shapely import LineString, Polygon, box

from gisroads.network.branches import branches_into

CAR_PARK = box(120, 40, 180, 90)


def _street_with_an_entrance():
    """A street along y = 0 across the data, an entrance up to a car park that splits round
    an island, a drive from its top into the lot, and a side street to the data's south
    edge."""
    return [LineString([(0, 0), (60, 0)]), LineString([(60, 0), (140, 0)]),
            LineString([(140, 0), (200, 0)]),
            LineString([(140, 0), (140, 10)]),                         # entrance
            LineString([(140, 10), (135, 20), (140, 30)]),             # round the island
            LineString([(140, 10), (145, 20), (140, 30)]),
            LineString([(140, 30), (140, 50)]),                        # into the lot
            LineString([(60, 0), (60, -100)])]                         # side street


def test_the_entrance_round_its_island_and_the_drive_are_taken_and_the_streets_kept():
    taken = branches_into(_street_with_an_entrance(), CAR_PARK)
    assert taken.tolist() == [False, False, False, True, True, True, True, False]


def test_a_branch_that_leaves_the_data_outside_the_car_park_stays():
    """The entrance goes on to the data's north edge: a road. Only the drive off it into
    the lot is the car park's."""
    lines = _street_with_an_entrance()
    lines.append(LineString([(140, 30), (100, 30), (100, 100)]))
    taken = branches_into(lines, CAR_PARK)
    assert np.flatnonzero(taken).tolist() == [6]


def test_a_branch_with_an_end_outside_the_car_park_stays_and_an_aisle_inside_it_counts():
    lines = _street_with_an_entrance()
    with_stub = lines + [LineString([(140, 10), (120, 10)])]           # a drive to a house
    assert np.flatnonzero(branches_into(with_stub, CAR_PARK)).tolist() == [6]
    with_aisle = lines + [LineString([(140, 50), (160, 50), (160, 85)])]
    assert np.flatnonzero(branches_into(with_aisle, CAR_PARK)).tolist() == [3, 4, 5, 6, 8]


def test_a_cul_de_sac_away_from_the_car_park_and_a_network_without_one_stay():
    lines = _street_with_an_entrance()[:3] + [LineString([(60, 0), (60, 50)])]
    assert not branches_into(lines, CAR_PARK).any()
    assert not branches_into(_street_with_an_entrance(), Polygon()).any()
    assert branches_into([], CAR_PARK).shape == (0,)
