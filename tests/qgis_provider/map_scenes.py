"""The scene the map-guided algorithms' tests share: a synthetic cloud and a road map off it."""
from pathlib import Path

from gisroads.io.vector import write_geopackage
from gisroads.synthetic import make_scene, write_cloud
from gisroads.synthetic.perturb import perturb_lines


def cloud_and_map(folder: Path, *, seed: int, features, density_per_m2: float) -> tuple:
    """``(scene, folder)``: a 300 m synthetic scene written to ``folder`` as cloud.laz, and
    its truth edges shifted 2.5 m and jittered 0.3 m as the osm_lines layer of map.gpkg, in
    geographic coordinates (the algorithms reproject it)."""
    scene = make_scene(seed=seed, size_m=(300.0, 300.0), features=features)
    write_cloud(scene, folder / "cloud.laz", density_per_m2=density_per_m2, seed=0)
    shifted = perturb_lines(scene.truth_edges, shift_m=2.5, jitter_m=0.3, seed=3)
    write_geopackage(folder / "map.gpkg", {"osm_lines": shifted.to_crs("EPSG:4326")})
    return scene, folder


def map_inputs(folder: Path) -> dict:
    """The INPUT cloud and MAP lines of a map-guided algorithm, from a ``cloud_and_map``
    folder."""
    return {"INPUT": folder / "cloud.laz", "MAP": f"{folder / 'map.gpkg'}|layername=osm_lines"}
