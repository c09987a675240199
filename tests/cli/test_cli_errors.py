"""Which errors the gisroads command turns into one line: gisroads' own (GisroadsError) and a
missing file print ``gisroads: error: ...`` and exit 2; anything else is a bug (a ValueError
from numpy or shapely among them) and keeps its traceback."""
import subprocess
import sys

import pytest

import gisroads.jobs
from gisroads.cli import main
from gisroads.errors import GisroadsError


def _raising(error):
    def describe_file(path):
        raise error
    return describe_file


@pytest.mark.parametrize("error, line", [
    (GisroadsError("x.gpkg: not a GeoPackage"), "gisroads: error: x.gpkg: not a GeoPackage"),
    (FileNotFoundError(2, "No such file or directory", "x.laz"),
     "gisroads: error: [Errno 2] No such file or directory: 'x.laz'"),
])
def test_gisroads_errors_and_missing_files_are_one_line(monkeypatch, capsys, tmp_path, error,
                                                        line):
    monkeypatch.setattr(gisroads.jobs, "describe_file", _raising(error))
    assert main(["info", str(tmp_path / "x.gpkg")]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.splitlines() == [line]


def test_a_plain_value_error_is_a_bug_and_escapes(monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(gisroads.jobs, "describe_file", _raising(ValueError("bug")))
    with pytest.raises(ValueError, match="^bug$") as raised:
        main(["info", str(tmp_path / "x.gpkg")])
    assert type(raised.value) is ValueError
    assert "gisroads: error" not in capsys.readouterr().err


def test_a_bug_prints_its_traceback_at_the_command_line(tmp_path):
    """As a user sees it: the gisroads command, its job raising numpy's kind of ValueError."""
    script = ("import sys, gisroads.jobs\n"
              "def describe_file(path):\n"
              "    raise ValueError('operands could not be broadcast together')\n"
              "gisroads.jobs.describe_file = describe_file\n"
              "from gisroads.cli import main\n"
              "sys.exit(main(sys.argv[1:]))\n")
    done = subprocess.run([sys.executable, "-c", script, "info", str(tmp_path / "x.gpkg")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 1
    assert done.stderr.startswith("Traceback (most recent call last):")
    assert "in describe_file" in done.stderr
    assert done.stderr.strip().splitlines()[-1] == (
        "ValueError: operands could not be broadcast together")
    assert "gisroads: error" not in done.stderr

