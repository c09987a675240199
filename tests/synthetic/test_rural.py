"""Synthetic rural tiles: earth tracks that are visible, of the widths drawn, seeded; tiles
without roads among them."""
import numpy as np
from scipy import ndimage
from skimage.morphology import skeletonize

from gisroads.synthetic.rural import render_rural_tile


def test_the_same_seed_gives_the_same_tile_and_another_seed_another():
    rgb, road = render_rural_tile(5, size_px=192)
    again, road_again = render_rural_tile(5, size_px=192)
    other, _ = render_rural_tile(6, size_px=192)
    np.testing.assert_array_equal(rgb, again)
    np.testing.assert_array_equal(road, road_again)
    assert np.abs(rgb.astype(int) - other).mean() > 5


def test_tracks_are_three_to_eight_metres_wide_and_stand_out_from_the_ground_beside():
    pixel_m = 0.5
    for seed in (0, 1, 2, 4, 5, 6, 7, 8):
        rgb, road = render_rural_tile(seed, pixel_m=pixel_m)
        assert road.any()
        # mean width: surface area over centre-line length, away from the tile's border
        inner = np.zeros_like(road)
        inner[40:-40, 40:-40] = True
        width_m = (road & inner).sum() * pixel_m / max(1, (skeletonize(road) & inner).sum())
        assert 2.5 < width_m < 9.0, (seed, width_m)
        # against the ground 2-4 m beside the tracks, shrubs and houses left out
        grey = rgb.astype(float).mean(axis=0)
        ring = (ndimage.binary_dilation(road, iterations=8)
                & ~ndimage.binary_dilation(road, iterations=4))
        core = ndimage.binary_erosion(road, iterations=2)
        beside = (ndimage.gaussian_filter(grey * ring, 8)
                  / np.maximum(ndimage.gaussian_filter(ring.astype(float), 8), 1e-6))
        smooth = ndimage.median_filter(grey, 5)
        contrast = np.median(np.abs(smooth[core] / beside[core] - 1))
        assert contrast > 0.05, (seed, contrast)


def test_some_tiles_have_no_road_and_some_are_one_colour_with_noise():
    tiles = [render_rural_tile(seed, size_px=96) for seed in range(60)]
    roadless = [k for k, (_, road) in enumerate(tiles) if not road.any()]
    plain = [k for k in roadless
             if max(np.ptp(ndimage.uniform_filter(band.astype(float), 15))
                    for band in tiles[k][0]) < 12]
    assert 4 <= len(roadless) <= 20 and 1 <= len(plain) < len(roadless)


def test_small_tiles_keep_the_ground_colour():
    """Noise smoothed over more than the tile is centred before it is scaled (a tiny
    spread of a nearly constant field must not blow its mean up)."""
    for seed in range(60):
        rgb, _ = render_rural_tile(seed, size_px=96)
        assert 40 < rgb.mean() < 220 and (rgb == 255).mean() < 0.2, seed
