"""Zhu & Mordohai's road extraction from airborne LiDAR: ground planes, intensity images, ..."""
from .ground import GroundPlanes, ground_planes
from .intensity import IntensityImages, image_grid, intensity_images, write_intensity_images
