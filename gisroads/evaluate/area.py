"""Grid metrics for road areas (Boyko & Funkhouser, 2011, section 3.1).

Predicted and reference road areas are boolean grids of square cells. With TP, FP, FN, TN
the cells that are road in both, only in the prediction, only in the reference, in neither:

- precision (correctness) ``p = TP / (TP + FP)``
- recall (completeness) ``r = TP / (TP + FN)``
- quality ``q = TP / (TP + FP + FN)``
- average spill size ``s = Σ_{c ∈ roadside_pred} d(c, roadside_ref) / |roadside_ref|``,
  metres: the distance from each predicted roadside cell to the nearest reference roadside
  cell (between cell centres), summed, per reference roadside cell.
- prevailing spill direction ``d = (FP - FN) / (FP + FN)``, in [-1, 1]: positive when the
  prediction spills out over the kerbs, negative when it stops short of them. The paper's
  text lost the minus sign and reports ``d`` in percent; this is the fraction.

Roadside cells are the boundary of the road area: road cells with at least one of their
four edge neighbours not road. Outside the grid counts as road here, so a road running off
the grid has no roadside along the grid edge: the extent's cut is not a kerb.

References
----------
Boyko, A., Funkhouser, T. (2011). Extracting roads from dense point clouds in large scale
urban environment. ISPRS Journal of Photogrammetry and Remote Sensing 66 (6), S2-S12.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import shapely
from affine import Affine
from rasterio.features import rasterize
from scipy import ndimage

from ..errors import GisroadsError
from .buffer import align_to_reference, typed_parts

_EDGE_NEIGHBOURS = ndimage.generate_binary_structure(2, 1)


def roadside(mask: np.ndarray) -> np.ndarray:
    """Boundary cells of a road mask: road cells with a non-road edge neighbour.

    Cells beyond the array count as road, so the array's edge is no boundary.
    """
    return mask & ~ndimage.binary_erosion(mask, structure=_EDGE_NEIGHBOURS, border_value=1)


@dataclass(frozen=True)
class AreaMetrics:
    """Boyko & Funkhouser's grid metrics (see the module docstring).

    Attributes
    ----------
    tp, fp, fn, tn : int
        Cell counts inside the valid area.
    precision, recall, quality : float
        In [0, 1]; precision is NaN when nothing is predicted.
    spill_size_m : float
        Average spill size ``s``, metres; NaN when the reference has no roadside cell.
    spill_direction : float
        ``(FP - FN) / (FP + FN)`` in [-1, 1]; NaN when there is no error at all.
    cell_m : float
        Cell side, metres.
    """

    tp: int
    fp: int
    fn: int
    tn: int
    precision: float
    recall: float
    quality: float
    spill_size_m: float
    spill_direction: float
    cell_m: float

    def as_dict(self) -> dict:
        """Plain ``{name: int or float}``, ready for JSON."""
        return {name: value if isinstance(value, int) else float(value)
                for name, value in asdict(self).items()}


def _ratio(numerator: int, denominator: int) -> float:
    return numerator / denominator if denominator else float("nan")


def area_metrics_from_masks(predicted, reference, *, cell_m: float,
                            valid=None) -> AreaMetrics:
    """Grid metrics of a predicted road mask against a reference mask.

    Parameters
    ----------
    predicted, reference : array_like of bool, shape (rows, cols)
        True where a cell is road.
    cell_m : float
        Cell side in metres (distances of the spill size).
    valid : array_like of bool, optional
        Cells to count; others are left out of every count and sum. Roadside cells are found
        on the whole grid, and a predicted roadside cell's distance is to the nearest
        reference roadside cell anywhere on the grid.

    Returns
    -------
    AreaMetrics

    Raises
    ------
    ValueError
        When the shapes differ or the reference has no road cell in the valid area.
    """
    pred = np.asarray(predicted, dtype=bool)
    ref = np.asarray(reference, dtype=bool)
    valid = np.ones(ref.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    if not pred.shape == ref.shape == valid.shape:
        raise GisroadsError(f"mask shapes differ: predicted {pred.shape}, reference "
                            f"{ref.shape}, valid {valid.shape}")
    tp = int(np.count_nonzero(pred & ref & valid))
    fp = int(np.count_nonzero(pred & ~ref & valid))
    fn = int(np.count_nonzero(~pred & ref & valid))
    tn = int(np.count_nonzero(~pred & ~ref & valid))
    if tp + fn == 0:
        raise GisroadsError("the reference has no road cell (in the valid area): "
                            "there is nothing to evaluate against")
    ref_side = roadside(ref)
    ref_side_count = int(np.count_nonzero(ref_side & valid))
    if ref_side_count:
        to_ref_side = ndimage.distance_transform_edt(~ref_side, sampling=cell_m)
        spill = float(to_ref_side[roadside(pred) & valid].sum()) / ref_side_count
    else:
        spill = float("nan")
    return AreaMetrics(tp=tp, fp=fp, fn=fn, tn=tn, precision=_ratio(tp, tp + fp),
                       recall=_ratio(tp, tp + fn), quality=_ratio(tp, tp + fp + fn),
                       spill_size_m=spill, spill_direction=_ratio(fp - fn, fp + fn),
                       cell_m=float(cell_m))


def area_metrics(predicted_polygons, reference_polygons, *, cell_m: float = 0.5, bounds=None,
                 valid_area=None) -> AreaMetrics:
    """Grid metrics of predicted road polygons against reference road polygons.

    Both polygon sets (and the valid area) are rasterised on one grid of ``cell_m`` cells
    aligned to multiples of ``cell_m``; a cell is road when its centre is inside a polygon
    (rasterio's ``all_touched=False``). Then :func:`area_metrics_from_masks`.

    Parameters
    ----------
    predicted_polygons, reference_polygons : GeoDataFrame, GeoSeries or sequence of
        (Multi)Polygon. The CRS rules of :mod:`gisroads.evaluate.buffer` apply.
    cell_m : float
        Cell side in metres (the paper's grid is 0.5 m).
    bounds : (xmin, ymin, xmax, ymax), optional
        Grid extent in the working CRS (the reference's, or its UTM zone when that is
        geographic), snapped outwards to the cell grid. By default the bounds of both polygon
        sets, snapped outwards and grown by one cell, so no road edge falls on the grid edge.
    valid_area : GeoDataFrame, GeoSeries or (Multi)Polygon, optional
        Only cells whose centre is inside are counted.

    Returns
    -------
    AreaMetrics
    """
    _, ref, (pred, area) = align_to_reference(reference_polygons, predicted_polygons,
                                              valid_area)
    polygon = (shapely.GeometryType.POLYGON,)
    ref = typed_parts(ref, polygon, layer="reference")
    pred = typed_parts(pred, polygon, layer="predicted")
    if bounds is None:
        bounds, margin = shapely.total_bounds(np.concatenate([ref, pred])), cell_m
    else:
        margin = 0.0
    xmin, ymin = np.floor(np.asarray(bounds[:2]) / cell_m) * cell_m - margin
    xmax, ymax = np.ceil(np.asarray(bounds[2:]) / cell_m) * cell_m + margin
    shape = (int(round((ymax - ymin) / cell_m)), int(round((xmax - xmin) / cell_m)))
    transform = Affine(cell_m, 0.0, xmin, 0.0, -cell_m, ymax)

    def burn(geoms) -> np.ndarray:
        if len(geoms) == 0:
            return np.zeros(shape, dtype=bool)
        return rasterize(geoms, out_shape=shape, transform=transform, fill=0,
                         default_value=1, dtype="uint8", all_touched=False).astype(bool)

    valid = None if area is None else burn(typed_parts(area, polygon, layer="valid area"))
    return area_metrics_from_masks(burn(pred), burn(ref), cell_m=cell_m, valid=valid)
