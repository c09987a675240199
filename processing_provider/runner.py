"""Running the external ``gisroads`` command: finding it, running a subcommand with its
progress, messages and cancel routed to QGIS's feedback, and the jobs' defaults it reports.

Standard library and qgis only: this module must import where gisroads cannot."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from functools import lru_cache

from qgis.core import QgsProcessingException, QgsSettings

from .environment import ready_executable
from .setup_gisroads import private_environment_folder

SETTING = "gisroads/executable"


def find_executable() -> str | None:
    """The external ``gisroads`` (see the module's doc for the order), None when none runs."""
    candidates = [os.environ.get("GISROADS_EXECUTABLE"), QgsSettings().value(SETTING, ""),
                  ready_executable(private_environment_folder()), shutil.which("gisroads")]
    for candidate in filter(None, candidates):
        try:
            done = subprocess.run([candidate, "--version"], capture_output=True, text=True,
                                  timeout=60)
        except (OSError, subprocess.SubprocessError):
            continue
        if done.returncode == 0 and done.stdout.startswith("gisroads"):
            return candidate
    return None


def run_external(executable: str, arguments: list[str], feedback) -> dict:
    """Run ``gisroads ARGUMENTS --json --progress-json``: progress and messages to
    ``feedback``, a cancel terminates it; returns its JSON result or raises
    QgsProcessingException with its one-line error."""
    command = [executable, *arguments, "--json", "--progress-json"]
    feedback.pushCommandInfo(" ".join(command))
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    stop = process.terminate  # one bound method, to disconnect what was connected
    feedback.canceled.connect(stop)
    messages = []
    try:
        for line in process.stderr:
            if line.startswith("{"):
                if feedback.isCanceled():
                    continue  # lines the command wrote before it was stopped
                event = json.loads(line)
                feedback.setProgress(100.0 * event["progress"])
                if event["message"]:
                    feedback.setProgressText(event["message"])
            elif line.strip():
                messages.append(line.strip())
                if line.startswith("gisroads: warning: "):
                    feedback.pushWarning(line.strip()[len("gisroads: warning: "):])
        stdout = process.stdout.read()
        status = process.wait()
    finally:
        feedback.canceled.disconnect(stop)
        if process.poll() is None:
            process.kill()
            process.wait()
        process.stdout.close()
        process.stderr.close()
    if feedback.isCanceled() or status == 130:
        raise QgsProcessingException("cancelled")
    if status != 0:
        errors = [m for m in messages if m.startswith("gisroads: error: ")]
        raise QgsProcessingException(
            errors[-1][len("gisroads: error: "):] if errors
            else f"{executable} failed (exit status {status}): {' '.join(messages[-3:])}")
    return json.loads(stdout)


@lru_cache(maxsize=4)
def external_defaults(executable: str) -> dict | None:
    """``{job: {keyword: default}}`` of the external command's jobs (``gisroads job
    --defaults``), asked once per executable; None when it cannot say (an older gisroads,
    a command that does not run)."""
    try:
        done = subprocess.run([executable, "job", "--defaults"], capture_output=True,
                              text=True, timeout=120)
        return json.loads(done.stdout) if done.returncode == 0 else None
    except (OSError, subprocess.SubprocessError, ValueError):
        return None
