"""File I/O: the only place gisroads touches files (LAS/LAZ, rasters, vector layers)."""
