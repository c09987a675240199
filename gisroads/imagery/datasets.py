"""The real imagery benchmark: every image of ``../shared/data/imagery`` with its road truth.

Each image is loaded as a :class:`BenchmarkImage`: a metric :class:`~gisroads.geo.GeoRaster`,
the truth as centre lines in the image's CRS, the area where that truth is complete, and the
buffer the issue scores it with.

============================  =========================================  ==========  =========
dataset                       truth                                      pixel       buffer
============================  =========================================  ==========  =========
``spacenet_vegas``            SpaceNet centre lines (GeoJSON)            0.3 m       3 m
``spacenet_paris``            OpenStreetMap centre lines (GeoJSON)       0.3 m       3 m
``massachusetts``             road-line masks, skeletonised              1.0 m       4 m
``deepglobe``                 road-area masks, skeletonised              0.5 m       3 m
``eth``                       road-area masks (>= 128), skeletonised     0.6 m (*)   3 m
============================  =========================================  ==========  =========

(*) assumed: the ETH set states no pixel size.

Georeferencing
    The SpaceNet GeoTIFFs are in EPSG:4326 (2.7e-6 degree pixels, 0.30 m north-south but
    0.24 m east-west at Las Vegas): they are warped with :func:`rasterio.warp.reproject`
    (bilinear for the image, nearest for the mask) onto a square 0.3 m grid in their UTM zone
    (Las Vegas: zone 11 N, EPSG:32611; Paris: zone 31 N, EPSG:32631), so the pipeline works in
    metres; the truth lines are reprojected with them. The PNG/JPEG sets carry no
    georeferencing: they get :data:`LOCAL_CRS`, a transverse Mercator in metres centred on
    (0 N, 0 E) that claims no real place, with the image's upper-left corner at
    ``(0, rows * pixel_m)``, so map coordinates are metres from the lower-left corner.
No-data
    Massachusetts tiles have pure-white (255, 255, 255) areas outside the orthophoto; white
    regions of at least ``min_nodata_m2`` are left out of the valid area (small white specks
    are roofs). ``10078750`` has all its roads there: it is loaded with ``scored=False``, an
    edge case for the pipeline, never a score. The warped SpaceNet images are valid inside the
    source image's footprint.
Truth from masks
    Masks are cleaned (holes under ``max_hole_m2`` filled) and skeletonised with
    :func:`gisroads.vectorize.skeleton.skeleton_lines`; end branches that reach less than 5 m
    beyond the road border (corners and bumps of area masks) are pruned. Truth lines are
    clipped to the valid area.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import geopandas as gpd
import numpy as np
import rasterio
import shapely
from affine import Affine
from pyproj import CRS, Transformer
from rasterio.errors import NotGeoreferencedWarning
from rasterio.enums import Resampling
from rasterio.warp import reproject
from scipy import ndimage

from ..errors import GisroadsError, MissingFileError
from ..geo import LOCAL_CRS, GeoRaster, local_transform
from ..io.raster import read_raster
from ..io.vector import read_layer
from ..vectorize.regions import segment_polygons
from ..vectorize.skeleton import skeleton_lines

DATA_DIR = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "imagery"
"""``../shared/data/imagery`` beside the repository."""

DATASETS = ("spacenet_vegas", "spacenet_paris", "massachusetts", "deepglobe", "eth")

SPACENET_PIXEL_M = 0.3
MASSACHUSETTS_PIXEL_M = 1.0
DEEPGLOBE_PIXEL_M = 0.5
ETH_PIXEL_M = 0.6
BUFFER_M = 3.0
MASSACHUSETTS_BUFFER_M = 4.0

_SPACENET = "SpaceNet (CosmiQ Works, DigitalGlobe/Maxar), CC BY-SA 4.0"
SOURCES = {
    "spacenet_vegas": f"{_SPACENET}; Las Vegas panchromatic tile and road labels from "
                      "CosmiQ/solaris @5315390, solaris/data/",
    "spacenet_paris": f"{_SPACENET}; Paris pan-sharpened RGB tile img1447 from the "
                      "CosmiQ/apls history; road lines from OpenStreetMap (ODbL)",
    "massachusetts": "Massachusetts Roads dataset (Mnih 2013) from "
                     "Riya-l209/road-extraction-unet @c56ce46; no licence stated there",
    "deepglobe": "DeepGlobe Road Extraction Challenge 2018 from "
                 "zlckanata/DeepGlobe-Road-Extraction-Challenge (PR 22); no licence stated "
                 "there",
    "eth": "ETH Zurich CIL road segmentation set from "
           "mhamas/road-extraction-from-aerial-images @2be7759; no licence stated there",
}
NOTES = {
    "spacenet_vegas": "truth incomplete: some streets unlabelled",
    "spacenet_paris": "OSM lines often 2-5 m off the road centre",
    "massachusetts": "pure-white no-data excluded",
    "deepglobe": "rural; many dirt tracks unlabelled",
    "eth": "pixel size assumed 0.6 m; alleys and parking unlabelled",
}
UNSCORED = {"massachusetts/10078750_15": "every road lies in no-data: an edge case, no score"}


@dataclass(frozen=True)
class BenchmarkImage:
    """One benchmark image with its truth, all in one metric CRS.

    Attributes
    ----------
    name : str
        ``dataset/stem``, e.g. ``massachusetts/10078660_15``.
    image : GeoRaster
        ``(bands, rows, cols)``: 1 band (Vegas, 11-bit in uint16) or RGB (uint8).
    truth : GeoDataFrame
        Truth centre lines (LineString) inside ``valid_area``; ``width_m`` where the truth is
        a mask (NaN for label lines).
    valid_area : shapely (Multi)Polygon
        Where the image has data and the truth applies; scores are clipped to it.
    buffer_m : float
        Buffer half-width of the completeness/correctness scores, metres.
    pixel_m : float
        Pixel side, metres.
    source : str
        Where the data comes from and its licence.
    truth_mask : GeoRaster or None
        The road mask the truth came from (Vegas: the rasterised labels), bool; None for
        Paris.
    scored : bool
        False for edge cases that must run but never score.
    note : str
        Known truth defects.
    """

    name: str
    image: GeoRaster
    truth: gpd.GeoDataFrame
    valid_area: shapely.Geometry
    buffer_m: float
    pixel_m: float
    source: str
    truth_mask: GeoRaster | None = None
    scored: bool = True
    note: str = ""

    @property
    def dataset(self) -> str:
        return self.name.split("/")[0]

    def crop(self, row: int, col: int, rows: int, cols: int) -> BenchmarkImage:
        """The window ``[row:row+rows, col:col+cols]`` with its truth and valid area."""
        height, width = self.image.shape
        if not (0 <= row < height and 0 <= col < width and rows > 0 and cols > 0):
            raise GisroadsError(f"window ({row}, {col}, {rows}, {cols}) lies outside the "
                                f"{height} x {width} image")
        window = (slice(row, row + rows), slice(col, col + cols))
        image = crop_raster(self.image, *window)
        mask = None if self.truth_mask is None else crop_raster(self.truth_mask, *window)
        area = shapely.intersection(self.valid_area, shapely.box(*image.bounds))
        return replace(self, image=image, truth_mask=mask, valid_area=area,
                       truth=_clip_frame(self.truth, area))


def crop_raster(raster: GeoRaster, rows: slice, cols: slice) -> GeoRaster:
    """The window ``rows``, ``cols`` (slices, pixels) of a raster, georeferenced (a view of
    its data, no copy)."""
    t = raster.transform
    x0 = t.c + cols.start * t.a + rows.start * t.b
    y0 = t.f + cols.start * t.d + rows.start * t.e
    return GeoRaster(raster.data[..., rows, cols], Affine(t.a, t.b, x0, t.d, t.e, y0),
                     raster.crs, raster.nodata)


def _clip_frame(lines: gpd.GeoDataFrame, area) -> gpd.GeoDataFrame:
    """Lines clipped to an area, one LineString per row, attributes kept."""
    if len(lines) == 0:
        return lines
    # GEOS 3.11 (Debian) sets a spurious floating-point flag on some of these intersections
    with np.errstate(invalid="ignore"):
        clipped = lines.set_geometry(lines.geometry.intersection(area))
    parts = clipped.explode(index_parts=False).reset_index(drop=True)
    keep = (parts.geom_type == "LineString") & ~parts.geometry.is_empty
    return parts[keep.to_numpy()].reset_index(drop=True)


def prune_spurs(lines: gpd.GeoDataFrame, spur_m: float) -> gpd.GeoDataFrame:
    """Drop short skeleton end branches and merge what remains.

    An end branch has one free end (no other line there). The skeleton of an area mask grows
    one towards every corner and every bump of the border; such a branch reaches from the
    road's middle to its border and a little beyond, so it is dropped when it is shorter
    than half the width of the widest line at its other end plus ``spur_m``. Isolated lines
    (two free ends) are held to half their own width plus ``spur_m``.

    Parameters
    ----------
    lines : GeoDataFrame
        Noded skeleton lines with ``width_m`` (from :func:`skeleton_lines`).
    spur_m : float
        Metres a branch may reach beyond the road border and still be a spur.
    """
    if len(lines) == 0:
        return lines
    geoms = lines.geometry.values
    width = lines["width_m"].to_numpy(float)
    ends = np.concatenate([shapely.get_coordinates(shapely.get_point(geoms, 0)),
                           shapely.get_coordinates(shapely.get_point(geoms, -1))])
    _, node, count = np.unique(np.round(ends / 1e-6).astype(np.int64), axis=0,
                               return_inverse=True, return_counts=True)
    node = node.ravel()
    node_width = np.zeros(len(count))
    np.maximum.at(node_width, node, np.tile(width, 2))
    free = (count[node] == 1).reshape(2, -1)
    start_node, end_node = node.reshape(2, -1)
    base_width = np.where(free[0], node_width[end_node], node_width[start_node])
    spur = free.any(axis=0) & (shapely.length(geoms) < 0.5 * base_width + spur_m)
    kept = lines[~spur]
    merged = shapely.get_parts(shapely.line_merge(shapely.union_all(kept.geometry.values)))
    if len(merged) == 0:
        return kept.iloc[:0]
    # widths follow the merged lines: length-weighted mean of the pieces each one contains
    owner = shapely.STRtree(merged).query_nearest(
        shapely.line_interpolate_point(kept.geometry.values, 0.5, normalized=True),
        all_matches=False, return_distance=False)[1]
    length = shapely.length(kept.geometry.values)
    width = np.bincount(owner, weights=length * kept["width_m"].to_numpy(float),
                        minlength=len(merged)) / np.maximum(
        np.bincount(owner, weights=length, minlength=len(merged)), 1e-9)
    return gpd.GeoDataFrame({"width_m": width}, geometry=merged, crs=lines.crs)


def mask_centrelines(mask: GeoRaster, *, spur_m: float = 5.0, max_hole_m2: float = 50.0,
                     min_length_m: float = 5.0) -> gpd.GeoDataFrame:
    """Truth centre lines of a road mask: filled, skeletonised, end branches pruned.

    Parameters
    ----------
    mask : GeoRaster
        2-D bool road mask.
    spur_m : float
        End branches reaching less than this beyond the road border are dropped (see
        :func:`prune_spurs`), metres.
    max_hole_m2 : float
        Holes of the mask up to this area are filled first (they would loop the skeleton),
        square metres.
    min_length_m : float
        Shorter lines left after pruning are dropped, metres.
    """
    road = np.asarray(mask.data, bool)
    background, count = ndimage.label(~road)
    # holes: background components that do not reach the image border
    border = np.concatenate([background[0], background[-1], background[:, 0],
                             background[:, -1]])
    small = np.bincount(background.ravel(), minlength=count + 1) * mask.pixel_size ** 2 \
        <= max_hole_m2
    small[border] = False
    small[0] = False
    road = road | small[background]
    lines = skeleton_lines(road, mask.transform, mask.crs, simplify_m=mask.pixel_size)
    lines = prune_spurs(lines, spur_m)
    return lines[lines.length >= min_length_m].reset_index(drop=True)


def _utm_grid(bounds, crs, pixel_m: float):
    """A north-up grid of ``pixel_m`` in the UTM zone of a geographic footprint, covering it."""
    footprint = gpd.GeoSeries([shapely.box(*bounds)], crs=crs)
    utm = footprint.estimate_utm_crs()
    ring = shapely.segmentize(shapely.box(*bounds), (bounds[2] - bounds[0]) / 64)
    to_utm = Transformer.from_crs(crs, utm, always_xy=True)
    x, y = to_utm.transform(*shapely.get_coordinates(ring).T)
    area = shapely.polygons(np.column_stack([x, y]))
    x0, y1 = np.floor(x.min() / pixel_m) * pixel_m, np.ceil(y.max() / pixel_m) * pixel_m
    cols = int(np.ceil((x.max() - x0) / pixel_m))
    rows = int(np.ceil((y1 - y.min()) / pixel_m))
    return utm, Affine(pixel_m, 0.0, x0, 0.0, -pixel_m, y1), (rows, cols), area


def warp_to_utm(path, pixel_m: float, *, resampling=Resampling.bilinear,
                nodata: float | None = 0) -> tuple[GeoRaster, shapely.Geometry]:
    """A geographic GeoTIFF warped onto a square ``pixel_m`` grid in its UTM zone.

    ``nodata`` is the source's no-data value; None when it has none: then the raster is
    warped as float32 with NaN outside the source footprint only, so that a mask's zeros
    or an image's black pixels stay data.

    Returns
    -------
    raster : GeoRaster
        ``nodata`` (NaN when None) outside the source footprint.
    footprint : shapely Polygon
        The source image's footprint in the UTM CRS, within the new grid.
    """
    with rasterio.open(path) as src:
        data, src_transform, src_crs, bounds = src.read(), src.transform, src.crs, src.bounds
    crs = CRS.from_user_input(src_crs.to_wkt())
    if not crs.is_geographic:
        raise GisroadsError(f"{path}: expected a geographic CRS, got {crs.name}")
    utm, transform, shape, footprint = _utm_grid(tuple(bounds), crs, pixel_m)
    if nodata is None:
        data, nodata = data.astype(np.float32), np.nan
    warped = np.full((len(data), *shape), nodata, dtype=data.dtype)
    reproject(source=data, destination=warped, src_transform=src_transform, src_crs=src_crs,
              dst_transform=transform, dst_crs=utm.to_wkt(), resampling=resampling,
              src_nodata=nodata, dst_nodata=nodata)
    raster = GeoRaster(warped, transform, utm, nodata)
    return raster, shapely.intersection(footprint, shapely.box(*raster.bounds))


def _label_lines(path, crs, area) -> gpd.GeoDataFrame:
    lines = read_layer(path, crs=crs)
    frame = gpd.GeoDataFrame({"width_m": np.full(len(lines), np.nan)},
                             geometry=shapely.force_2d(lines.geometry.values), crs=crs)
    return _clip_frame(frame, area)


def load_spacenet_vegas(data_dir=DATA_DIR) -> BenchmarkImage:
    """The SpaceNet Las Vegas panchromatic tile (11-bit), its labels and their mask."""
    folder = Path(data_dir) / "spacenet"
    image, footprint = warp_to_utm(folder / "vegas_pan_road_mask_input.tif", SPACENET_PIXEL_M)
    mask, _ = warp_to_utm(folder / "vegas_pan_road_mask.tif", SPACENET_PIXEL_M,
                          resampling=Resampling.nearest)
    truth = _label_lines(folder / "vegas_pan_roads.geojson", image.crs, footprint)
    return BenchmarkImage("spacenet_vegas/vegas_pan", image, truth, footprint, BUFFER_M,
                          SPACENET_PIXEL_M, SOURCES["spacenet_vegas"],
                          truth_mask=GeoRaster(mask.data[0] > 0, mask.transform, mask.crs),
                          note=NOTES["spacenet_vegas"])


def load_spacenet_paris(data_dir=DATA_DIR) -> BenchmarkImage:
    """The SpaceNet Paris pan-sharpened RGB tile img1447 and its OpenStreetMap lines."""
    folder = Path(data_dir) / "spacenet"
    image, footprint = warp_to_utm(folder / "RGB-PanSharpen_img1447.tif", SPACENET_PIXEL_M)
    truth = _label_lines(folder / "OSMroads_img1447.geojson", image.crs, footprint)
    return BenchmarkImage("spacenet_paris/img1447", image, truth, footprint, BUFFER_M,
                          SPACENET_PIXEL_M, SOURCES["spacenet_paris"],
                          note=NOTES["spacenet_paris"])


def _plain_image(path, pixel_m: float) -> GeoRaster:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        raster = read_raster(path, pixel_size=pixel_m, crs=LOCAL_CRS)
    return GeoRaster(raster.data[:3], local_transform(raster.shape, pixel_m), LOCAL_CRS)


def _mask_record(name, dataset, image, road, valid, *, pixel_m, buffer_m):
    mask = GeoRaster(road & valid, image.transform, image.crs)
    area = shapely.box(*image.bounds)
    if not valid.all():
        area = segment_polygons(np.where(valid, 0, -1).astype(np.int32), 1, image.transform)[0]
        area = shapely.Polygon() if area is None else area
    truth = _clip_frame(mask_centrelines(mask), area)
    return BenchmarkImage(f"{dataset}/{name}", image, truth, area, buffer_m, pixel_m,
                          SOURCES[dataset], truth_mask=mask,
                          scored=f"{dataset}/{name}" not in UNSCORED,
                          note=UNSCORED.get(f"{dataset}/{name}", NOTES[dataset]))


def massachusetts_valid(rgb: np.ndarray, pixel_m: float, *,
                        min_nodata_m2: float = 10_000.0) -> np.ndarray:
    """Valid pixels of a Massachusetts tile: not in a pure-white region of ``min_nodata_m2``."""
    white = (np.asarray(rgb) == 255).all(axis=0)
    label, count = ndimage.label(white)
    size = np.bincount(label.ravel(), minlength=count + 1) * pixel_m ** 2
    nodata = size >= min_nodata_m2
    nodata[0] = False
    return ~nodata[label]


def _paths(folder: Path, pattern: str, stems) -> list[Path]:
    paths = sorted(folder.glob(pattern))
    return paths if stems is None else [p for p in paths if p.stem.split("_sat")[0] in stems]


def load_massachusetts(data_dir=DATA_DIR, *, stems=None) -> list[BenchmarkImage]:
    """The Massachusetts Roads tiles (1 m), no-data masked, ``10078750`` unscored; only
    those named in ``stems`` (``"10078735_15"``) when given."""
    folder = Path(data_dir) / "massachusetts"
    records = []
    for path in _paths(folder / "images", "*.png", stems):
        image = _plain_image(path, MASSACHUSETTS_PIXEL_M)
        road = _plain_image(folder / "masks" / path.name, MASSACHUSETTS_PIXEL_M).data[0] > 127
        valid = massachusetts_valid(image.data, MASSACHUSETTS_PIXEL_M)
        records.append(_mask_record(path.stem, "massachusetts", image, road, valid,
                                    pixel_m=MASSACHUSETTS_PIXEL_M,
                                    buffer_m=MASSACHUSETTS_BUFFER_M))
    return records


def load_deepglobe(data_dir=DATA_DIR, *, stems=None) -> list[BenchmarkImage]:
    """The DeepGlobe tiles (0.5 m) with their road-area masks; only ``stems`` (``"104"``)
    when given."""
    folder = Path(data_dir) / "deepglobe"
    records = []
    for path in _paths(folder, "*_sat.jpg", stems):
        image = _plain_image(path, DEEPGLOBE_PIXEL_M)
        stem = path.stem.removesuffix("_sat")
        road = _plain_image(folder / f"{stem}_mask.png", DEEPGLOBE_PIXEL_M).data[0] > 127
        records.append(_mask_record(stem, "deepglobe", image, road,
                                    np.ones(image.shape, bool), pixel_m=DEEPGLOBE_PIXEL_M,
                                    buffer_m=BUFFER_M))
    return records


def load_eth(data_dir=DATA_DIR, *, stems=None) -> list[BenchmarkImage]:
    """The ETH CIL images (0.6 m assumed) with their road-area masks (threshold 128); only
    ``stems`` (``"satImage_010"``) when given."""
    folder = Path(data_dir) / "eth"
    records = []
    for path in _paths(folder / "images", "*.png", stems):
        image = _plain_image(path, ETH_PIXEL_M)
        road = _plain_image(folder / "groundtruth" / path.name, ETH_PIXEL_M).data[0] >= 128
        records.append(_mask_record(path.stem, "eth", image, road, np.ones(image.shape, bool),
                                    pixel_m=ETH_PIXEL_M, buffer_m=BUFFER_M))
    return records


_LOADERS = {"spacenet_vegas": lambda d: [load_spacenet_vegas(d)],
            "spacenet_paris": lambda d: [load_spacenet_paris(d)],
            "massachusetts": load_massachusetts, "deepglobe": load_deepglobe, "eth": load_eth}


def benchmark_images(data_dir=DATA_DIR, *, datasets=DATASETS) -> list[BenchmarkImage]:
    """Every benchmark image of the chosen datasets (see the module docstring).

    Parameters
    ----------
    data_dir : str or Path
        The ``imagery`` folder of the shared data.
    datasets : sequence of str
        Names from :data:`DATASETS`.

    Raises
    ------
    ValueError
        Unknown dataset name.
    FileNotFoundError
        ``data_dir`` missing.
    """
    unknown = set(datasets) - set(DATASETS)
    if unknown:
        raise GisroadsError(f"unknown datasets {sorted(unknown)}; choose from {DATASETS}")
    if not Path(data_dir).is_dir():
        raise MissingFileError(f"{data_dir}: no imagery benchmark folder")
    return [record for name in datasets for record in _LOADERS[name](data_dir)]
