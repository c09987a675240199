"""Benchmark for the road database update: a road truth edited into a "database" with known
changes, and the precision and recall of each change class found by :func:`conflate`.

:func:`edit_database` deletes roads (the comparison should report them ``new``), adds fake
roads (``missing``), shifts roads sideways (``moved``) and changes widths (``width``), each on
a disjoint random share of the truth's lines, seeded. :func:`score_changes` scores the change
layers against that edit; :func:`pooled_scores` does both over several seeded edits.

Fake roads must lie where there is no road in the data, not merely none in the truth's
centre lines: a hand-digitised truth leaves out car-park aisles, service ways and other paved
areas, and a fake placed over them is seen (rightly) by a good extraction and confirmed. So
fakes keep their clearance from the truth's lines and from ``pavement`` (every other paved
area the truth knows of: :func:`truth_pavement`), and that clearance should be at least the
comparison's search distance (15 m), within which a fake could be matched as "moved" onto
real pavement.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely

from ..errors import GisroadsError
from .conflate import conflate

EDITS = ("unchanged", "shifted", "width", "fake")
"""Values of :attr:`EditedDatabase.edit`."""
CLASSES = ("missing", "moved", "width", "new")
"""The change classes :func:`score_changes` scores."""


@dataclass
class EditedDatabase:
    """A truth edited into a database.

    Attributes
    ----------
    database : GeoDataFrame
        The edited lines: the truth's columns plus ``db_id`` (1001, 1002 ... in the truth's
        order, fakes last), in the truth's CRS.
    edit : Series
        Per ``db_id``, what was done to the line (:data:`EDITS`).
    deleted : GeoDataFrame
        The truth lines left out of the database.
    """

    database: gpd.GeoDataFrame
    edit: pd.Series
    deleted: gpd.GeoDataFrame


FUSA_UNLABELLED_PAVEMENT = (
    (277845.0, 6122400.0, 277885.0, 6122500.0),
    (277750.0, 6122250.0, 277765.0, 6122350.0),
)
"""Paved areas of fusa.laz that its digitised truth leaves out of every layer, as boxes
(xmin, ymin, xmax, ymax; EPSG:32754) from its README ("Ambiguities and decisions"): the wide
grey car park between RA and NER, and the grey strip along the west edge south of the
carriageway. (The kerbed strip at x 277762-277770 beside WR lies within a fake's clearance of
WR anyway.)"""


def truth_pavement(folder, boxes=()) -> gpd.GeoSeries:
    """Every paved area a ground-truth folder knows of besides its road centre lines:
    ``road_area.geojson``, the ``service.geojson`` lines buffered by half their ``width_m``
    (car-park aisles, access ways), and ``boxes`` (xmin, ymin, xmax, ymax, in the truth's
    CRS) for paved areas the truth describes but leaves out; files that are absent are
    skipped."""
    folder = Path(folder)
    parts, crs = [], None
    for name in ("road_area.geojson", "service.geojson"):
        if not (folder / name).is_file():
            continue
        layer = gpd.read_file(folder / name)
        crs = crs or layer.crs
        geoms = layer.to_crs(crs).geometry
        if name == "service.geojson":
            geoms = geoms.buffer(layer["width_m"].astype(float) / 2.0
                                 if "width_m" in layer else 0.0)
        parts.extend(geoms.values)
    if crs is None:
        crs = gpd.read_file(folder / "centrelines.geojson").crs
    parts.extend(shapely.box(*box) for box in boxes)
    return gpd.GeoSeries(parts, crs=crs)


def _fake_lines(truth: gpd.GeoDataFrame, count: int, length_m: tuple[float, float],
                clearance_m: float, rng: np.random.Generator,
                pavement: np.ndarray | None = None) -> np.ndarray:
    """``count`` straight lines inside the truth's bounds, each at least ``clearance_m`` from
    every truth line, from ``pavement`` (geometries) and from the other fakes."""
    xmin, ymin, xmax, ymax = truth.total_bounds
    n_candidates = 200 * max(count, 1)
    start = rng.uniform([xmin, ymin], [xmax, ymax], (n_candidates, 2))
    heading = rng.uniform(0.0, np.pi, n_candidates)
    end = start + rng.uniform(*length_m, n_candidates)[:, None] * np.column_stack(
        [np.cos(heading), np.sin(heading)])
    candidates = shapely.linestrings(np.stack([start, end], axis=1))
    inside = ((end[:, 0] >= xmin) & (end[:, 0] <= xmax)
              & (end[:, 1] >= ymin) & (end[:, 1] <= ymax))
    occupied = list(shapely.force_2d(truth.geometry.values))
    if pavement is not None:
        occupied.extend(shapely.force_2d(np.asarray(pavement, dtype=object)))
    clear = shapely.distance(candidates, shapely.union_all(occupied)) >= clearance_m
    chosen: list = []
    for candidate in candidates[inside & clear]:  # a few hundred candidates, greedily
        if len(chosen) == count:
            break
        if not chosen or min(shapely.distance(candidate, chosen)) >= clearance_m:
            chosen.append(candidate)
    if len(chosen) < count:
        raise GisroadsError(f"room for only {len(chosen)} of {count} fake roads "
                            f"{clearance_m} m clear of the truth and its pavement")
    return np.array(chosen, dtype=object)


def _clearance(tree: shapely.STRtree, xy: np.ndarray, own: np.ndarray,
               reach_m: float = 50.0) -> np.ndarray:
    """Distance (metres, at most ``reach_m``) from each point to the nearest line of
    ``tree`` other than line ``own`` of the same row."""
    point, line = tree.query(shapely.points(xy), predicate="dwithin", distance=reach_m)
    other = line != own[point]
    distance = np.full(len(xy), reach_m)
    np.minimum.at(distance, point[other], shapely.distance(
        shapely.points(xy[point[other]]), tree.geometries[line[other]]))
    return distance


def edit_database(truth: gpd.GeoDataFrame, *, seed: int = 0, delete_share: float = 0.2,
                  fake_share: float = 0.1, shift_share: float = 0.1,
                  width_share: float = 0.1, shift_m: tuple[float, float] = (5.0, 10.0),
                  width_change_m: tuple[float, float] = (3.0, 6.0),
                  fake_length_m: tuple[float, float] = (40.0, 80.0),
                  fake_clearance_m: float = 25.0, pavement=None,
                  width_field: str = "width_m") -> EditedDatabase:
    """Edit truth centre lines into a road database with known changes.

    Parameters
    ----------
    truth : GeoDataFrame
        Road centre lines in a metre CRS with a width column ``width_field`` (metres).
    seed : int
    delete_share, fake_share, shift_share, width_share : float
        Shares of the truth's line count deleted, added as fakes, shifted and given another
        width. Deleted, shifted and re-widened lines are disjoint.
    shift_m : (float, float)
        Range of the sideways shift (metres), perpendicular to the line's chord, either side.
    width_change_m : (float, float)
        Range of the width change (metres): added, or subtracted when that leaves at least
        3 m.
    fake_length_m : (float, float)
        Range of the fake roads' lengths (metres): straight lines.
    fake_clearance_m : float
        Fake roads keep at least this distance (metres) from the truth, from ``pavement``
        and from each other.
    pavement : GeoSeries or array of geometries, optional
        Paved areas the truth's lines do not hold (car-park aisles, service ways, squares:
        :func:`truth_pavement`), in the truth's CRS: fakes keep clear of them too, so that a
        fake is a road that is not there.
    width_field : str

    Returns
    -------
    EditedDatabase
    """
    rng = np.random.default_rng(seed)
    n = len(truth)
    counts = np.rint(np.array([delete_share, shift_share, width_share]) * n).astype(int)
    if counts.sum() > n:
        raise GisroadsError("the deleted, shifted and re-widened shares exceed the whole")
    kind = np.full(n, "unchanged", dtype=object)
    order = rng.permutation(n)
    bounds = np.cumsum(counts)
    kind[order[:bounds[0]]] = "deleted"
    kind[order[bounds[0]:bounds[1]]] = "shifted"
    kind[order[bounds[1]:bounds[2]]] = "width"

    lines = truth.reset_index(drop=True).copy()
    geoms = shapely.force_2d(np.asarray(lines.geometry.values, dtype=object))
    shifted = np.flatnonzero(kind == "shifted")
    chord = (shapely.get_coordinates(shapely.get_point(geoms[shifted], -1))
             - shapely.get_coordinates(shapely.get_point(geoms[shifted], 0)))
    normal = np.column_stack([-chord[:, 1], chord[:, 0]]) / np.hypot(*chord.T)[:, None]
    offset = normal * rng.uniform(*shift_m, len(shifted))[:, None]
    # shift to the side away from other roads: a line moved onto its neighbour (one
    # carriageway onto the other) would be that neighbour, not a moved road
    middle = shapely.get_coordinates(shapely.line_interpolate_point(geoms[shifted], 0.5,
                                                                    normalized=True))
    others = shapely.STRtree(geoms)
    room = np.stack([_clearance(others, middle + side * offset, shifted)
                     for side in (1.0, -1.0)], axis=1)
    offset *= np.where(room[:, 0] >= room[:, 1], 1.0, -1.0)[:, None]
    coords, part = shapely.get_coordinates(geoms[shifted], return_index=True)
    geoms[shifted] = shapely.set_coordinates(geoms[shifted].copy(), coords + offset[part])
    lines[lines.geometry.name] = gpd.GeoSeries(geoms, crs=truth.crs)

    rewidened = np.flatnonzero(kind == "width")
    change = rng.uniform(*width_change_m, len(rewidened))
    width = lines[width_field].to_numpy(float, copy=True)
    narrower = width[rewidened] - change
    width[rewidened] = np.where(narrower >= 3.0, narrower, width[rewidened] + change)
    lines[width_field] = width

    n_fakes = int(round(fake_share * n))
    fakes = lines.iloc[rng.integers(0, n, n_fakes)].copy()
    fakes[fakes.geometry.name] = gpd.GeoSeries(
        _fake_lines(truth, n_fakes, fake_length_m, fake_clearance_m, rng,
                    None if pavement is None else _in_crs(pavement, truth.crs)),
        index=fakes.index, crs=truth.crs)
    kept = kind != "deleted"
    database = pd.concat([lines[kept], fakes], ignore_index=True)
    database.insert(0, "db_id", np.arange(1001, 1001 + len(database), dtype=np.int64))
    edit = pd.Series(np.r_[kind[kept], np.full(n_fakes, "fake", dtype=object)],
                     index=database["db_id"].to_numpy(), name="edit")
    return EditedDatabase(gpd.GeoDataFrame(database, geometry=truth.geometry.name,
                                           crs=truth.crs),
                          edit, truth.reset_index(drop=True)[~kept])


def _in_crs(geometries, crs) -> np.ndarray:
    """Geometries as an array in ``crs`` (a GeoSeries/GeoDataFrame is reprojected)."""
    if isinstance(geometries, (gpd.GeoSeries, gpd.GeoDataFrame)):
        geometries = (geometries.to_crs(crs) if geometries.crs is not None
                      else geometries).geometry.values
    return np.asarray(geometries, dtype=object)


def _covered_share(lines: np.ndarray, cover: np.ndarray, buffer_m: float) -> np.ndarray:
    """Share of each line's length within ``buffer_m`` of any of ``cover``."""
    if len(cover) == 0:
        return np.zeros(len(lines))
    zone = shapely.buffer(shapely.union_all(cover), buffer_m)
    return shapely.length(shapely.intersection(lines, zone)) / shapely.length(lines)


def _precision_recall(flagged: int, flagged_right: int, actual: int, actual_found: int) -> dict:
    return {"precision": flagged_right / flagged if flagged else float("nan"),
            "recall": actual_found / actual if actual else float("nan"),
            "flagged": flagged, "actual": actual}


def score_changes(changes: dict[str, gpd.GeoDataFrame], edited: EditedDatabase, *,
                  id_field: str = "db_id", buffer_m: float = 3.0,
                  min_cover: float = 0.5) -> dict[str, dict]:
    """Precision and recall of each change class against the edit.

    ``missing`` (fake roads flagged ``missing`` in ``proposed_update``), ``moved`` (shifted
    roads in ``moved``) and ``width`` (re-widened roads with ``width_changed`` in
    ``confirmed``) are counted by database id; ``new`` by line: a deleted truth line is found
    when at least ``min_cover`` of its length lies within ``buffer_m`` (metres) of the
    ``new`` layer, and a ``new`` line is right when as much of it lies near deleted lines.

    Returns
    -------
    dict
        Per class: ``precision``, ``recall`` (NaN when nothing is flagged, or nothing to
        find), ``flagged`` and ``actual`` counts.
    """
    update = changes["proposed_update"]
    flagged_ids = {
        "missing": update.loc[update["change"] == "missing", id_field],
        "moved": changes["moved"]["db_id"],
        "width": changes["confirmed"].loc[changes["confirmed"]["width_changed"], "db_id"],
    }
    actual_edit = {"missing": "fake", "moved": "shifted", "width": "width"}
    scores = {}
    for name, flagged in flagged_ids.items():
        actual = set(edited.edit.index[edited.edit == actual_edit[name]])
        flagged = set(flagged)
        scores[name] = _precision_recall(len(flagged), len(flagged & actual), len(actual),
                                         len(flagged & actual))
    crs = edited.database.crs
    new = np.asarray(changes["new"].to_crs(crs).geometry.values, dtype=object)
    deleted = shapely.force_2d(np.asarray(edited.deleted.geometry.values, dtype=object))
    right = int((_covered_share(new, deleted, buffer_m) >= min_cover).sum())
    found = int((_covered_share(deleted, new, buffer_m) >= min_cover).sum())
    scores["new"] = _precision_recall(len(new), right, len(deleted), found)
    return scores


def pooled_scores(extracted: gpd.GeoDataFrame, truth: gpd.GeoDataFrame, seeds, *,
                  width_field: str = "width_m", **edit_options) -> dict:
    """Edit ``truth`` once per seed, compare ``extracted`` with each edit and pool the scores.

    Parameters
    ----------
    extracted : GeoDataFrame or callable
        Extracted centre lines (any CRS), or ``extracted(database)`` that gives them for
        an edited database (an extraction that learns from the database).
    truth : GeoDataFrame
        Truth centre lines in a metre CRS with widths in ``width_field`` (metres).
    seeds : iterable of int
    width_field : str
    **edit_options
        Passed to :func:`edit_database`.

    Returns
    -------
    dict
        Per class of :func:`score_changes`: precision and recall pooled over the edits
        (means weighted by the flagged and the actual counts; None without any), and the
        pooled counts.
    """
    totals = {name: {"right": 0.0, "flagged": 0, "found": 0.0, "actual": 0}
              for name in CLASSES}
    for seed in seeds:
        edited = edit_database(truth, seed=seed, width_field=width_field, **edit_options)
        lines = extracted(edited.database) if callable(extracted) else extracted
        changes = conflate(lines, edited.database, id_field="db_id",
                           width_field=width_field)
        for name, score in score_changes(changes, edited).items():
            total = totals[name]
            total["flagged"] += score["flagged"]
            total["actual"] += score["actual"]
            total["right"] += score["precision"] * score["flagged"] if score["flagged"] else 0
            total["found"] += score["recall"] * score["actual"] if score["actual"] else 0
    return {name: {"precision": t["right"] / t["flagged"] if t["flagged"] else None,
                   "recall": t["found"] / t["actual"] if t["actual"] else None,
                   "flagged": t["flagged"], "actual": t["actual"]}
            for name, t in totals.items()}
