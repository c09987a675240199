"""Memory follows the points: a cloud with stray points 3000 km from the rest gets tiles
only where its points are, in bounded memory (issue 12, item 0)."""
import json
import subprocess
import sys
import textwrap

import laspy
import numpy as np

from gisroads.tiling.tiles import tile_grid
from gisroads.synthetic import make_scene, write_cloud


def test_tiles_exist_only_where_points_are():
    xy = [np.array([[0.0, 0.0], [10.0, 20.0]]), np.array([[3_000_000.0, 3_000_000.0]])]
    extent = (0.0, 0.0, 3_000_000.0, 3_000_000.0)
    tiles = tile_grid(extent, tile_m=300.0, overlap_m=100.0, points_xy=xy)
    # the full grid would hold 15,000 x 15,000 tiles
    assert len(tiles) == 2
    for point in (xy[0][0], xy[1][0]):
        holding = [t for t in tiles if t.bounds[0] <= point[0] <= t.bounds[2]
                   and t.bounds[1] <= point[1] <= t.bounds[3]]
        cores = [t for t in holding if t.core[0] <= point[0] <= t.core[2]
                 and t.core[1] <= point[1] <= t.core[3]]
        assert holding and cores
    # without points the same extent and with every point: the usual grid
    full = tile_grid((0, 0, 700, 500), tile_m=300, overlap_m=100)
    dense = tile_grid((0, 0, 700, 500), tile_m=300, overlap_m=100,
                      points_xy=[np.random.default_rng(0).uniform((0, 0), (700, 500),
                                                                   (5000, 2))])
    assert dense == full


def test_cloud_with_points_3000_km_away_runs_in_bounded_memory(tmp_path):
    scene = make_scene(seed=2, size_m=(300.0, 300.0), features=("buildings", "trees"))
    path = tmp_path / "scene.laz"
    write_cloud(scene, path, density_per_m2=2.0, seed=2)
    las = laspy.read(path)
    # centimetre scale: 3000 km does not fit millimetres in LAS's 32-bit coordinates
    header = laspy.LasHeader(point_format=las.header.point_format.id,
                             version=str(las.header.version))
    header.scales, header.offsets = np.array([0.01] * 3), las.header.offsets
    header.vlrs = las.header.vlrs
    out = laspy.LasData(header)
    shift = np.array([0.0, 0.0, 3_000_000.0, -3_000_000.0])
    out.x = np.concatenate([las.x, las.x[:2] + shift[2:]])
    out.y = np.concatenate([las.y, las.y[:2] + 3_000_000.0])
    out.z = np.concatenate([las.z, las.z[:2]])
    for name in ("intensity", "return_number", "number_of_returns", "classification"):
        out[name] = np.concatenate([las[name], las[name][:2]])
    far = tmp_path / "stray.laz"
    out.write(far)
    # 3 GiB of address space: the bounding box's grid or rasters would need far more
    script = textwrap.dedent(f"""
        import json, resource
        resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30))
        from gisroads.lidar.pipeline import extract_roads
        out = {{}}
        for cue in ("intensity", "evidence"):
            roads = extract_roads({str(far)!r}, cue=cue)
            out[cue] = float(roads.network.centrelines.length.sum())
        print(json.dumps(out))
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    lengths = json.loads(done.stdout.strip().splitlines()[-1])
    assert lengths["intensity"] > 500 and lengths["evidence"] > 500
