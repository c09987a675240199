"""Seeded synthetic scenes with exact ground truth, to test the road methods on.

:func:`make_scene` lays a scene out (roads, parking lots, buildings, trees, cars, markings,
a cliff and a bridge), :func:`make_canal_scene` a canal town of brick-paved streets;
``scene.truth`` is its road network. :func:`render_cloud` /
:func:`write_cloud` simulate an airborne LiDAR survey of it, :func:`road_surface_mask` tells
which points lie on a road; :func:`render_image` / :func:`write_image` make an R, G, B, NIR
orthoimage and a DSM; :func:`perturb_lines` and :func:`degrade_mask` make an old map or an
imperfect segmentation of it, with known errors; :func:`render_rural_tile` a rural aerial
tile (earth tracks, villages, river beds) and its road mask, for training road models.
"""
from .canal import make_canal_scene
from .cloud import render_cloud, road_surface_mask, write_cloud
from .image import render_image, write_image
from .network import FEATURES, Scene, make_scene
from .perturb import degrade_mask, perturb_lines
from .rural import render_rural_tile

__all__ = ["FEATURES", "Scene", "make_scene", "make_canal_scene", "render_cloud",
           "road_surface_mask", "write_cloud", "render_image", "write_image", "degrade_mask",
           "perturb_lines", "render_rural_tile"]
