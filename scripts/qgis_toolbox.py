"""The Processing toolbox filtered to gisroads, as the QGIS desktop shows it: shared by the
desktop screenshots (``qgis_dialog_screenshot.py``) and the desktop tests, which run inside
``qgis --code``."""
from qgis.PyQt.QtCore import QModelIndex, Qt
from qgis.utils import plugins


def show_gisroads_toolbox():
    """The Processing toolbox dock, shown, filtered to gisroads, every group open."""
    toolbox = plugins["processing"].toolbox
    toolbox.show()
    toolbox.searchBox.setText("gisroads")
    toolbox.algorithmTree.expandAll()
    return toolbox


def toolbox_rows(tree, index=None, depth: int = 0) -> list:
    """The tree's rows as shown, two spaces of indent per level."""
    model, rows = tree.model(), []
    index = QModelIndex() if index is None else index
    for row in range(model.rowCount(index)):
        child = model.index(row, 0, index)
        rows.append("  " * depth + model.data(child, Qt.DisplayRole))
        rows += toolbox_rows(tree, child, depth + 1)
    return rows
