"""Which errors the QGIS algorithms turn into a QgsProcessingException (one message, exit 1
in qgis_process): gisroads' own (GisroadsError) and a missing file; anything else is a bug
(a ValueError from numpy or shapely among them) and keeps its traceback."""
import pytest
from qgis.core import QgsProcessingException, QgsProcessingFeedback

from gisroads.errors import GisroadsError
from processing_provider.convert import gisroads_errors


@pytest.mark.parametrize("error", [
    GisroadsError("x.gpkg: not a GeoPackage"),
    FileNotFoundError(2, "No such file or directory", "x.laz"),
])
def test_gisroads_errors_and_missing_files_become_processing_exceptions(error):
    with pytest.raises(QgsProcessingException) as raised:
        with gisroads_errors(QgsProcessingFeedback()):
            raise error
    assert str(raised.value) == str(error)


def test_a_plain_value_error_is_a_bug_and_escapes():
    with pytest.raises(ValueError, match="^bug$") as raised:
        with gisroads_errors(QgsProcessingFeedback()):
            raise ValueError("bug")
    assert type(raised.value) is ValueError


def test_open_network_refuses_a_file_that_is_not_a_geopackage(run_algorithm, tmp_path):
    path = tmp_path / "roads.gpkg"
    path.write_text("not a database")
    with pytest.raises(QgsProcessingException, match="roads.gpkg: not a GeoPackage"):
        run_algorithm("openroadnetwork", {"INPUT": str(path)})
