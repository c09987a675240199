"""Set up gisroads: the plugin makes gisroads' own Python environment in the QGIS profile,
from a local package index built here (never the internet): a stand-in gisroads wheel with
a dependency, both in a wheelhouse that pip reads through PIP_NO_INDEX / PIP_FIND_LINKS, as
a user's pip.conf would point it at an index."""
import base64
import hashlib
import json
import os
import re
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from processing_provider.environment import (STAMP, SetupError, _stream, bundled_wheel,
                                             create_environment, interpreter,
                                             ready_executable)

from tests.qgis_provider.conftest import QgisProcess, plugin_profile

FAKE_VERSION = "gisroads 0.0.1 (stand-in)"


def _wheel(folder: Path, name: str, version: str, files: dict, *, requires=(),
           scripts=None) -> Path:
    """A pure-Python wheel written by hand: ``files`` (path: text), its dependencies and
    console scripts (name: "module:function")."""
    info = f"{name}-{version}.dist-info"
    content = dict(files)
    content[f"{info}/METADATA"] = "\n".join(
        ["Metadata-Version: 2.1", f"Name: {name}", f"Version: {version}",
         *[f"Requires-Dist: {r}" for r in requires]]) + "\n"
    content[f"{info}/WHEEL"] = ("Wheel-Version: 1.0\nGenerator: gisroads-tests\n"
                                "Root-Is-Purelib: true\nTag: py3-none-any\n")
    if scripts:
        content[f"{info}/entry_points.txt"] = "[console_scripts]\n" + "".join(
            f"{k} = {v}\n" for k, v in scripts.items())
    record = []
    for path, text in content.items():
        digest = base64.urlsafe_b64encode(hashlib.sha256(text.encode()).digest()).rstrip(b"=")
        record.append(f"{path},sha256={digest.decode()},{len(text.encode())}")
    content[f"{info}/RECORD"] = "\n".join(record + [f"{info}/RECORD,,"]) + "\n"
    path = folder / f"{name}-{version}-py3-none-any.whl"
    with zipfile.ZipFile(path, "w") as archive:
        for member, text in content.items():
            archive.writestr(member, text)
    return path


@pytest.fixture(scope="module")
def wheelhouse(tmp_path_factory) -> tuple[Path, Path]:
    """(a local index holding a stand-in gisroads wheel and its dependency, that wheel)."""
    house = tmp_path_factory.mktemp("wheelhouse")
    _wheel(house, "gisroads_standin_dep", "1.0",
           {"gisroads_standin_dep/__init__.py": "READY = True\n"})
    main = ("import gisroads_standin_dep\n"
            "def main():\n"
            f"    print({FAKE_VERSION!r} if gisroads_standin_dep.READY else 'broken')\n")
    wheel = _wheel(house, "gisroads", "0.0.1", {"gisroads_standin/__init__.py": main},
                   requires=["gisroads_standin_dep>=1.0"],
                   scripts={"gisroads": "gisroads_standin:main"})
    return house, wheel


@pytest.fixture
def local_index(wheelhouse, monkeypatch):
    house, wheel = wheelhouse
    monkeypatch.setenv("PIP_NO_INDEX", "1")
    monkeypatch.setenv("PIP_FIND_LINKS", str(house))
    return wheel


def test_set_up_makes_an_environment_from_the_configured_index(local_index, tmp_path):
    folder = tmp_path / "profile" / "gisroads" / "environment"
    steps = []
    executable = create_environment(folder, local_index,
                                    progress=lambda f, m: steps.append((f, m)))
    assert Path(executable).parent.parent == folder and ready_executable(folder) == executable
    ran = subprocess.run([executable, "--version"], capture_output=True, text=True)
    assert ran.stdout.strip() == FAKE_VERSION  # its dependency came from the index too
    stamp = json.loads((folder / STAMP).read_text())
    assert stamp["version"] == FAKE_VERSION and stamp["wheel"] == local_index.name
    fractions = [f for f, _ in steps]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert any(m.startswith("Processing ") or m.startswith("Collecting ") for _, m in steps)
    # the environment is QGIS's interpreter's (here: the Python running the tests)
    assert stamp["python"] == str(interpreter())


def test_an_index_without_the_dependencies_says_what_to_do_and_leaves_nothing(
        wheelhouse, tmp_path, monkeypatch):
    _, wheel = wheelhouse
    lonely = tmp_path / "index"
    lonely.mkdir()
    monkeypatch.setenv("PIP_NO_INDEX", "1")
    monkeypatch.setenv("PIP_FIND_LINKS", str(lonely))
    folder = tmp_path / "environment"
    with pytest.raises(SetupError) as raised:
        create_environment(folder, wheel)
    message = str(raised.value)
    assert "\n" not in message
    assert "package index" in message and "gisroads_standin_dep" in message
    assert "PIP_INDEX_URL" in message and "gisroads/executable" in message
    assert not folder.exists() and ready_executable(folder) is None


def test_a_cancelled_set_up_leaves_nothing(local_index, tmp_path):
    folder = tmp_path / "environment"
    with pytest.raises(SetupError, match="cancelled"):
        create_environment(folder, local_index, cancelled=lambda: True)
    assert not folder.exists()


def test_a_cancel_stops_pip_while_it_is_silent():
    """A cancel is seen within a second even while pip prints nothing (a large download)."""
    started = time.monotonic()
    with pytest.raises(SetupError, match="cancelled"):
        _stream([sys.executable, "-c", "import time; time.sleep(60)"],
                progress=lambda f, m: None, share=(0.1, 0.9), expected=1, env=None,
                cancelled=lambda: time.monotonic() - started > 1.0)
    assert time.monotonic() - started < 3.0


def _fake_python(folder: Path, version: str, venv_error: str | None = None) -> Path:
    """An executable standing in for a Python: says its version, fails ``-m venv``."""
    script = folder / "python"
    script.write_text("#!/bin/sh\n"
                      f'if [ "$1" = "-c" ]; then echo "{version}"; exit 0; fi\n'
                      f'echo "{venv_error}" >&2; exit 1\n')
    script.chmod(0o755)
    return script


def test_an_old_python_or_one_without_venv_is_named_with_the_fix(local_index, tmp_path):
    old = _fake_python(tmp_path, "3 9")
    with pytest.raises(SetupError, match=r"is Python 3\.9; gisroads needs Python 3\.11"):
        create_environment(tmp_path / "a", local_index, python=old)
    (tmp_path / "b").mkdir()
    bare = _fake_python(tmp_path / "b", "3 11",
                        "Error: ensurepip is not available on this system")
    with pytest.raises(SetupError) as raised:
        create_environment(tmp_path / "c", local_index, python=bare)
    assert str(bare) in str(raised.value) and "python3-venv" in str(raised.value)
    assert "ensurepip is not available" in str(raised.value)
    assert not (tmp_path / "c").exists()
    with pytest.raises(SetupError, match="no gisroads wheel"):
        create_environment(tmp_path / "d", tmp_path / "none.whl")
    with pytest.raises(SetupError, match="does not run"):
        create_environment(tmp_path / "e", local_index, python=tmp_path / "no-python")


def test_the_plugin_zip_carries_the_gisroads_wheel(plugin_zip, tmp_path):
    with zipfile.ZipFile(plugin_zip) as archive:
        archive.extractall(tmp_path)
    wheel = bundled_wheel(tmp_path / "gisroads_qgis")
    assert wheel is not None and wheel.name.startswith("gisroads-0.1.0-")
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    assert {"gisroads/cli/__init__.py", "gisroads/learn/models/road_convnet.onnx",
            "gisroads/_styles/road_centrelines.qml"} <= names
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    with zipfile.ZipFile(wheel) as archive:
        assert "gisroads = " in archive.read(entry_points).decode()


@pytest.fixture(scope="module")
def stock_qgis_process(plugin_zip, tmp_path_factory, wheelhouse) -> QgisProcess:
    """qgis_process as a stock QGIS runs it (system Python alone, no gisroads anywhere),
    its pip pointed at the local index."""
    home = tmp_path_factory.mktemp("stock_qgis_home")
    runner = plugin_profile(plugin_zip, home)
    del runner.env["PYTHONPATH"]
    runner.env["PATH"] = os.pathsep.join(
        folder for folder in runner.env["PATH"].split(os.pathsep)
        if not (Path(folder) / "gisroads").exists())
    runner.env.update(PIP_NO_INDEX="1", PIP_FIND_LINKS=str(wheelhouse[0]))
    runner.enabled = runner("plugins", "enable", "gisroads_qgis")
    return runner


def _listed(result) -> list[str]:
    return re.findall(r"^\s*(gisroads:\S+)", result.stdout, flags=re.M)


def test_a_stock_qgis_sets_gisroads_up_and_then_lists_its_algorithms(stock_qgis_process,
                                                                     wheelhouse):
    before = stock_qgis_process("list")
    assert "Traceback" not in before.stdout + before.stderr
    assert _listed(before) == ["gisroads:setupgisroads"]
    (message,) = [line for line in before.stderr.splitlines() if line.startswith("gisroads:")]
    assert "qgis_process run gisroads:setupgisroads" in message
    assert "/usr/bin/python3" in message and "pipx" not in message
    done = stock_qgis_process("--json", "run", "gisroads:setupgisroads", "--",
                              f"WHEEL={wheelhouse[1]}")
    executable = json.loads(done.stdout)["results"]["EXECUTABLE"]
    profile = stock_qgis_process.env["HOME"] + "/.local/share/QGIS/QGIS3/profiles/default/"
    assert executable == profile + "gisroads/environment/bin/gisroads"
    stamp = json.loads(Path(profile, "gisroads/environment", STAMP).read_text())
    assert stamp["python"].startswith("/usr/bin/python3")  # QGIS's own interpreter
    after = stock_qgis_process("list")
    assert _listed(after) == ["gisroads:cityblocks", "gisroads:imageryroadnetwork",
                              "gisroads:lidarroadnetwork", "gisroads:openroadnetwork",
                              "gisroads:ribbonsnakeroads", "gisroads:roadrastertonetwork",
                              "gisroads:setupgisroads", "gisroads:syntheticroadscene",
                              "gisroads:trainroadmodel"]
    assert "setupgisroads" not in after.stderr  # no set-up message any more
