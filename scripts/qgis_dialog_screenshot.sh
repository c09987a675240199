#!/bin/sh
# Usage: scripts/qgis_dialog_screenshot.sh OUT_DIR ALGORITHM_ID 'JSON_PARAMETERS'
# The QGIS desktop under Xvfb, started the usual way (system Python, no .venv-qgis, no
# QGIS_CUSTOM_CONFIG_PATH), with the plugin zip (make plugin) in a throwaway profile:
# screenshots of ALGORITHM_ID's dialog before and after a run
# (scripts/qgis_dialog_screenshot.py). With GISROADS_EXECUTABLE set, the plugin runs in
# external-tool mode through that command.
set -eu
out=$(realpath "$1")
repo=$(dirname "$(dirname "$(realpath "$0")")")
home=$(mktemp -d)
trap 'rm -rf "$home"' EXIT
profile="$home/.local/share/QGIS/QGIS3/profiles/default"
mkdir -p "$profile/python/plugins" "$profile/QGIS" "$home/runtime" "$out"
chmod 700 "$home/runtime"
rm -f "$out/shot.log"
python3 -m zipfile -e "$repo/dist/gisroads_qgis.zip" "$profile/python/plugins"
printf '[PythonPlugins]\ngisroads_qgis=true\nprocessing=true\n[qgis]\nshowTips=false\ncheckVersion=false\n' \
    > "$profile/QGIS/QGIS3.ini"
status=0
env -u QGIS_CUSTOM_CONFIG_PATH -u QGIS_OPTIONS_PATH HOME="$home" XDG_RUNTIME_DIR="$home/runtime" SHOT_DIR="$out" SHOT_SCRIPTS="$repo/scripts" SHOT_ALGORITHM="$2" \
    SHOT_PARAMETERS="${3:-{\}}" PYTHONPATH='' \
    timeout 600 xvfb-run -a -s "-screen 0 1600x1000x24" \
    qgis --nologo --noversioncheck --code "$repo/scripts/qgis_dialog_screenshot.py" || status=$?
cat "$out/shot.log" 2>/dev/null || echo "no log: QGIS ended before opening the dialog"
exit $status
