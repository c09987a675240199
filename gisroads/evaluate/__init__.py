"""Evaluation of extracted road networks against a reference.

- :mod:`.buffer`: completeness, correctness, quality and RMS of centre lines (Wiedemann 1998),
  and the input rules (CRS, empty layers) every metric shares;
- :mod:`.area`: grid precision, recall, quality, spill size and direction of road areas
  (Boyko & Funkhouser 2011);
- :mod:`.topology`: connected components and junction precision and recall;
- :mod:`.apls`: the APLS path-length score (Van Etten et al. 2018, SpaceNet);
- :mod:`.report`: all of them in one call, and a text summary.
"""
from .apls import apls_score
from .area import AreaMetrics, area_metrics, area_metrics_from_masks
from .buffer import BufferMetrics, buffer_metrics, match_layers
from .report import evaluate_network, format_report
from .topology import junction_metrics, topology_metrics

__all__ = [
    "AreaMetrics", "BufferMetrics", "apls_score", "area_metrics", "area_metrics_from_masks",
    "buffer_metrics", "evaluate_network", "format_report", "junction_metrics", "match_layers",
    "topology_metrics",
]
