"""QGIS provider tests: the plugin zip run by the real qgis_process.bin, and in-process runs.

They need Debian's QGIS. Where ``qgis`` cannot be imported they are skipped, so the core
suite runs in any Python, unless GISROADS_REQUIRE_QGIS is set (``make test`` and CI set it):
then a missing QGIS fails the run.
"""
import json
import os
import site
import subprocess
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
QGIS_PROCESS = "/usr/bin/qgis_process.bin"

try:
    import qgis.core  # noqa: F401
except ImportError:
    if os.environ.get("GISROADS_REQUIRE_QGIS"):
        raise
    collect_ignore_glob = ["test_*.py"]


@pytest.fixture(scope="session")
def plugin_zip() -> Path:
    subprocess.run([str(REPO / "scripts" / "build_plugin.sh")], check=True,
                   capture_output=True)
    return REPO / "dist" / "gisroads_qgis.zip"


class QgisProcess:
    """qgis_process.bin with the plugin installed from the zip into a throwaway profile."""

    def __init__(self, home: Path):
        self.env = {
            "HOME": str(home), "PATH": os.environ["PATH"], "QT_QPA_PLATFORM": "offscreen",
            "XDG_RUNTIME_DIR": str(home / "runtime"),
            # Third-party packages (laspy, lazrs, shapely 2) from the QGIS venv; a PYTHONPATH
            # entry gets no .pth processing, so the editable gisroads install stays out and
            # the plugin runs the gisroads copy inside the zip.
            "PYTHONPATH": os.pathsep.join(site.getsitepackages()),
        }
        (home / "runtime").mkdir(mode=0o700, exist_ok=True)

    def __call__(self, *args, check=True):
        result = subprocess.run([QGIS_PROCESS, *args], env=self.env, capture_output=True,
                                text=True, timeout=600)
        if check and result.returncode != 0:
            raise AssertionError(f"qgis_process {' '.join(args)} failed "
                                 f"({result.returncode}):\n{result.stdout}\n{result.stderr}")
        return result

    def run(self, algorithm, **params):
        args = ["--json", "run", f"gisroads:{algorithm}", "--"]
        args += [f"{k}={v}" for k, v in params.items()]
        return json.loads(self(*args).stdout)["results"]


def plugin_profile(plugin_zip: Path, home: Path) -> QgisProcess:
    """qgis_process with the plugin zip unpacked into the profile of a throwaway ``home``
    (not yet enabled: the caller may still change the runner's environment)."""
    plugins = home / ".local/share/QGIS/QGIS3/profiles/default/python/plugins"
    plugins.mkdir(parents=True)
    with zipfile.ZipFile(plugin_zip) as archive:
        archive.extractall(plugins)
    return QgisProcess(home)


@pytest.fixture(scope="session")
def qgis_process(plugin_zip, tmp_path_factory) -> QgisProcess:
    if not Path(QGIS_PROCESS).exists():
        pytest.fail(f"{QGIS_PROCESS} missing: run scripts/setup.sh")
    runner = plugin_profile(plugin_zip, tmp_path_factory.mktemp("qgis_home"))
    runner("plugins", "enable", "gisroads_qgis")
    return runner


@pytest.fixture(scope="session")
def scene_dir(qgis_process, tmp_path_factory) -> Path:
    """A small synthetic scene made by the plugin through qgis_process."""
    out = tmp_path_factory.mktemp("scene")
    qgis_process.run("syntheticroadscene", WIDTH=300, HEIGHT=300, SEED=3, DENSITY=2,
                     PIXEL=1.0, OUTPUT_FOLDER=out)
    return out


@pytest.fixture(scope="session")
def run_algorithm(qgis_app):
    """``run_algorithm(name, params, feedback=None)``: a gisroads algorithm run in this
    process (prepare + runPrepared), for tests of cancel and of in-process conversions."""
    from qgis.core import QgsApplication, QgsProcessingContext, QgsProcessingFeedback

    from processing_provider.provider import GisroadsProvider

    provider = GisroadsProvider()
    registry = QgsApplication.processingRegistry()
    registry.addProvider(provider)

    def run(name, params, feedback=None):
        algorithm = registry.createAlgorithmById(f"gisroads:{name}")
        context = QgsProcessingContext()
        feedback = feedback or QgsProcessingFeedback()
        assert algorithm.prepare(params, context, feedback)
        return algorithm.runPrepared(params, context, feedback)

    yield run
    registry.removeProvider(provider)


@pytest.fixture
def run_and_load(run_algorithm, qgis_processing):
    """``run_and_load(algorithm, params, existing=())``: an algorithm instance run in this
    process, its outputs then loaded as the toolbox dialog loads them (Processing's
    handleAlgorithmResults) into the cleared project holding the layers ``existing``;
    returns ``{layer name: ticked}`` of the layer tree, top to bottom. The project is
    cleared again afterwards."""
    from processing.gui.Postprocessing import handleAlgorithmResults
    from qgis.core import QgsProcessingContext, QgsProcessingFeedback, QgsProject

    project = QgsProject.instance()

    def run(algorithm, params, existing=()):
        project.clear()
        for layer in existing:
            project.addMapLayer(layer)
        context = QgsProcessingContext()
        context.setProject(project)
        feedback = QgsProcessingFeedback()
        assert algorithm.prepare(params, context, feedback)
        algorithm.runPrepared(params, context, feedback)
        assert handleAlgorithmResults(algorithm, context, feedback, parameters=params)
        return {node.name(): node.itemVisibilityChecked()
                for node in project.layerTreeRoot().findLayers()}

    yield run
    project.clear()
