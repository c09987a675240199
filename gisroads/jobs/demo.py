"""The demo job: both road pipelines on the bundled real data."""
from __future__ import annotations

from pathlib import Path

import geopandas as gpd
import shapely

from ..evaluate import evaluate_network, format_report
from ..geo import CENTRELINES
from ..io.raster import read_raster
from ..io.vector import read_layer
from ..progress import Progress, report, scaled, to_json
from ..resources import demo_dir
from .imagery import image_job
from .lidar import lidar_job

DEMO_IMAGE = "spacenet_paris_img1447.tif"
DEMO_IMAGE_TRUTH = "osm_roads_img1447.geojson"
DEMO_CLOUD = "ign_lidar_hd_0292_6833_thinned.laz"


def demo_job(out_dir, *, data_dir=None, progress: Progress = None) -> dict:
    """The demo on the bundled real data: both road pipelines, their GeoPackages and PNGs.

    ``data_dir`` defaults to the bundled sample data: the package data of a wheel
    (``gisroads/_demo``), the repository's ``data/demo`` in a checkout
    (:func:`gisroads.resources.demo_dir`); its README gives the sources and licences.

    * the imagery pipeline on a SpaceNet Paris tile (RGB, 0.3 m), scored against its
      OpenStreetMap centre lines (``image_roads.gpkg``, ``image_roads.png``,
      ``image_evaluation.json``);
    * the LiDAR pipeline on a thinned IGN LiDAR HD tile of a town (1 km², 0.29 points/m²,
      processed at the coarser cell its density allows) with the default cue, every cue the
      cloud carries (``lidar_roads.gpkg``, ``lidar_roads.png``), and with the paper's
      intensity cue alone (``lidar_intensity_roads.gpkg``, ``lidar_intensity_roads.png``).
    """
    data, out = Path(demo_dir() if data_dir is None else data_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    image = image_job(data / DEMO_IMAGE, out / "image_roads.gpkg",
                      quicklook=out / "image_roads.png",
                      progress=scaled(progress, 0.0, 0.3, "imagery"))
    footprint = gpd.GeoDataFrame(geometry=[shapely.box(*read_raster(data / DEMO_IMAGE).bounds)],
                                 crs=read_layer(out / "image_roads.gpkg", CENTRELINES).crs)
    evaluation = evaluate_network(read_layer(out / "image_roads.gpkg", CENTRELINES),
                                  read_layer(data / DEMO_IMAGE_TRUTH), valid_area=footprint)
    (out / "image_evaluation.json").write_text(to_json(evaluation))
    lidar = lidar_job(data / DEMO_CLOUD, out / "lidar_roads.gpkg",
                      quicklook=out / "lidar_roads.png",
                      progress=scaled(progress, 0.3, 0.85, "LiDAR"))
    intensity = lidar_job(data / DEMO_CLOUD, out / "lidar_intensity_roads.gpkg",
                          cue="intensity", quicklook=out / "lidar_intensity_roads.png",
                          progress=scaled(progress, 0.85, 1.0, "LiDAR, the paper's cue"))
    report(progress, 1.0, "done")
    return {"image": image, "image_evaluation": evaluation,
            "image_report": format_report(evaluation), "lidar": lidar,
            "lidar_intensity": intensity}
