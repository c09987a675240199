"""``gisroads snakes --quicklook``: the ribbons drawn over the curb attractor, on fusa."""
import json
import subprocess
import sys

from matplotlib.image import imread


def test_snakes_draws_its_ribbons_over_the_attractor(lidar_dir, tmp_path):
    truth = lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson"
    png = tmp_path / "snakes.png"
    done = subprocess.run([sys.executable, "-m", "gisroads.cli", "snakes",
                           str(lidar_dir / "fusa.laz"), str(truth), "-o",
                           str(tmp_path / "s.gpkg"), "--quicklook", str(png), "--json"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["quicklook"] == str(png)
    pixels = imread(png)[..., :3]
    # orange ribbons and red centre lines over the grey-scale attractor (grey where only
    # the extent term holds, black, white on the kerbs; the page around it is white)
    orange = (pixels[..., 0] > 0.6) & (pixels[..., 1] > 0.3) & (pixels[..., 1] < 0.8) \
        & (pixels[..., 2] < 0.4)
    grey = (abs(pixels[..., 0] - pixels[..., 1]) < 0.02) \
        & (abs(pixels[..., 1] - pixels[..., 2]) < 0.02) & (pixels[..., 0] > 0.1) \
        & (pixels[..., 0] < 0.99)
    assert orange.mean() > 0.02 and grey.mean() > 0.1    # measured 0.024, 0.264
    bad = subprocess.run([sys.executable, "-m", "gisroads.cli", "snakes",
                          str(lidar_dir / "fusa.laz"), str(truth), "-o",
                          str(tmp_path / "t.gpkg"), "--quicklook", str(tmp_path / "x.jpg")],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and ".png" in bad.stderr
