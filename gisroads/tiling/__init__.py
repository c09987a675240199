"""Overlapping tiles and the on-disk tile store: how every method cuts a large input.

The tile grid, cores and stitching (:mod:`.tiles`; Zhu & Mordohai's 300 m tiles that overlap
by 100 m) and the point store that reads a cloud once into the grid (:mod:`.tilestore`).
The LiDAR pipeline, the imagery pipeline's tiled network stage and the ribbon snakes'
point buckets share them.
"""
