"""Whole jobs, composed from the stages: what the CLI subcommands and the QGIS algorithms run.

Each job reads files, calls pure stages, and writes its outputs through temporary files.
One module per method (:mod:`.lidar`, :mod:`.imagery`, :mod:`.snakes`, :mod:`.network`,
:mod:`.update`), the evaluation and demo jobs, and what they share (:mod:`.common`: the
inputs they read, :func:`network_summary`, the no-road warning). Every job is importable
from here.
"""
import inspect
import math

from ..errors import GisroadsError
from ..options import keyword_defaults
from .common import (VECTOR_SUFFIXES, describe_file, network_summary, parse_metres,
                     read_image, stage_default)
from .demo import DEMO_CLOUD, DEMO_IMAGE, DEMO_IMAGE_TRUTH, demo_job
from .evaluate import evaluate_job, synth_job
from .imagery import (grouping_job, image_job, road_parts_job, segmentation_job,
                      train_job)
from .lidar import (blocks_job, evidence_job, ground_intensity_job, lidar_job,
                    lidar_segmentation_job, likelihood_job, min_cover_job,
                    rectangles_network_job, tag_job, train_lidar_job)
from .network import junctions_job, linking_job, vectorize_job
from .snakes import attractor_job, register_job, snakes_job
from .update import update_job

JOBS = {function.__name__: function for function in (
    evaluate_job, synth_job, image_job, train_job, blocks_job, evidence_job,
    ground_intensity_job, lidar_job, lidar_segmentation_job, likelihood_job, min_cover_job,
    rectangles_network_job, tag_job, vectorize_job, attractor_job, register_job, snakes_job,
    update_job, train_lidar_job, segmentation_job, grouping_job, road_parts_job,
    linking_job, junctions_job)}
"""The jobs by name, for ``gisroads job NAME`` (the QGIS algorithms' external-tool mode)."""


def job_defaults(name: str) -> dict:
    """``{keyword: default}`` of the job ``name`` (those with a default, ``progress``
    excepted; the fields of an options object one by one), as JSON takes them: tuples as
    lists, also inside mappings. An infinite default (no limit) has no JSON form and is left
    out."""
    return {keyword: _as_json(default)
            for keyword, default in keyword_defaults(JOBS[name]).items()
            if default is not inspect.Parameter.empty and keyword != "progress"
            and not (isinstance(default, float) and not math.isfinite(default))}


def _as_json(value):
    if isinstance(value, (tuple, list)):
        return [_as_json(v) for v in value]
    if isinstance(value, dict):
        return {k: _as_json(v) for k, v in value.items()}
    return value


def run_job(name: str, arguments: dict, progress=None) -> dict:
    """The job ``name`` called with ``arguments`` (keywords), and ``progress`` when it
    reports progress."""
    if name not in JOBS:
        raise GisroadsError(f"no job {name!r}; the jobs: {', '.join(sorted(JOBS))}")
    function = JOBS[name]
    unknown = set(arguments) - set(keyword_defaults(function))
    if unknown:
        raise GisroadsError(f"{name} takes no {', '.join(sorted(unknown))}")
    if "progress" in inspect.signature(function).parameters:
        arguments = {**arguments, "progress": progress}
    return function(**arguments)


__all__ = [
    "VECTOR_SUFFIXES", "describe_file", "network_summary", "parse_metres", "read_image",
    "stage_default", "DEMO_CLOUD", "DEMO_IMAGE", "DEMO_IMAGE_TRUTH", "demo_job",
    "evaluate_job", "synth_job", "image_job", "train_job", "blocks_job", "evidence_job",
    "ground_intensity_job", "lidar_job", "lidar_segmentation_job", "likelihood_job",
    "min_cover_job", "rectangles_network_job", "tag_job", "vectorize_job", "attractor_job",
    "register_job", "snakes_job", "update_job", "train_lidar_job", "segmentation_job",
    "grouping_job", "road_parts_job", "linking_job", "junctions_job", "JOBS", "job_defaults",
    "run_job",
]
