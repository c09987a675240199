"""A wheel built from the checkout carries everything gisroads reads at run time.

The wheel is built (``pip wheel --no-deps``) from a copy of the checkout's files, installed
into a fresh venv in a temporary folder and run from a temporary working directory, so
nothing of the checkout can be imported or read: the venv borrows only the heavy
dependencies, by a ``.pth`` naming the running environment's site-packages folders (whose
``.pth`` files, the checkout's editable install among them, are not run). Its
``gisroads demo`` must then write GeoPackages whose ``layer_styles`` hold the styles.
"""
from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow


def _checkout_copy(target: Path) -> Path:
    """The checkout's files (tracked and new, not ignored) copied to ``target``: a build
    there leaves no ``build/`` in the checkout and takes no stale file from one."""
    listed = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=REPO,
                            check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        source = REPO / name
        if source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            (target / name).write_bytes(source.read_bytes())
    return target


def _dependency_folders() -> list[str]:
    """The running environment's site-packages folders (not the checkout)."""
    return [p for p in sys.path if Path(p).name in {"site-packages", "dist-packages"}
            and Path(p).is_dir() and not Path(p).resolve().is_relative_to(REPO / "gisroads")]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("wheel")
    source = _checkout_copy(root / "src")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                    str(root / "dist"), str(source)], check=True, cwd=root,
                   capture_output=True)
    (built,) = (root / "dist").glob("gisroads-*.whl")
    return built


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> tuple[Path, dict]:
    """A venv outside the checkout with only the wheel installed, and its environment."""
    root = tmp_path_factory.mktemp("venv")
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_path("
                                "'purelib'))"], check=True, capture_output=True,
                               text=True).stdout.strip())
    (site / "_borrowed_dependencies.pth").write_text("\n".join(_dependency_folders()) + "\n")
    # pip >= 22.3 installs into another interpreter's environment (--python)
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q",
                    "--no-deps", str(wheel)], check=True, capture_output=True)
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "PYTHONHOME"}}
    env["OPENBLAS_NUM_THREADS"] = "1"
    try:  # Debian's pyproj finds PROJ's data under sys.prefix, which a venv moves
        import pyproj
        env.setdefault("PROJ_DATA", pyproj.datadir.get_data_dir())
    except ImportError:
        pass
    return venv, env


def test_wheel_carries_the_styles_and_the_demo_data(wheel):
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
        for folder, packaged in [(REPO / "styles", "gisroads/_styles"),
                                 (REPO / "data" / "demo", "gisroads/_demo")]:
            files = sorted(p for p in folder.iterdir() if p.is_file())
            assert files
            for path in files:
                assert f"{packaged}/{path.name}" in names
                assert archive.read(f"{packaged}/{path.name}") == path.read_bytes()


def test_installed_wheel_runs_the_demo_with_styled_outputs(installed, tmp_path):
    venv, env = installed
    where = subprocess.run(
        [venv / "bin" / "python", "-c", "import gisroads, gisroads.resources as r; "
         "print(gisroads.__file__); print(r.styles_dir()); print(r.demo_dir())"],
        cwd=tmp_path, env=env, check=True, capture_output=True, text=True).stdout.split()
    for path in where:  # the installed copy, its package data: nothing of the checkout
        assert Path(path).resolve().is_relative_to(venv.resolve()), where
        assert not Path(path).resolve().is_relative_to(REPO)
    run = subprocess.run([venv / "bin" / "gisroads", "demo", "--out", "demo", "--json"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads(run.stdout)
    gpkgs = [Path(result[key]["gpkg"]) for key in ("image", "lidar", "lidar_intensity")]
    repo_styles = {p.stem: p.read_text(encoding="utf-8") for p in (REPO / "styles").glob("*.qml")}
    for gpkg in gpkgs:
        gpkg = gpkg if gpkg.is_absolute() else tmp_path / gpkg
        con = sqlite3.connect(gpkg)
        try:
            layers = {r[0] for r in con.execute(
                "SELECT table_name FROM gpkg_contents WHERE data_type = 'features'")}
            stored = dict(con.execute("SELECT f_table_name, styleQML FROM layer_styles"
                                      " WHERE useAsDefault"))
        finally:
            con.close()
        assert {"road_centrelines", "road_polygons", "junctions"} <= layers
        assert set(stored) == layers & set(repo_styles), gpkg
        for name, qml in stored.items():
            assert qml == repo_styles[name]


def test_plugin_metadata_has_the_fields_qgis_reads_and_no_placeholder():
    import configparser
    metadata = configparser.ConfigParser()
    metadata.read(REPO / "metadata.txt", encoding="utf-8")
    general = metadata["general"]
    for field in ("name", "qgisMinimumVersion", "description", "about", "version", "author"):
        assert general.get(field, "").strip(), field
    assert general["hasProcessingProvider"] == "yes"
    assert tuple(int(p) for p in general["qgisMinimumVersion"].split(".")) <= (3, 22)
    assert not [v for v in general.values() if "example." in v]
