"""A throwaway PostgreSQL + PostGIS cluster for tests: Debian's ``postgresql`` and ``postgis``
packages (``scripts/setup.sh apt`` installs them), ``initdb`` into a temporary folder, the
server listening on a Unix socket in that folder only (no TCP), trust authentication.

PostgreSQL refuses to run as root: as root the cluster is run as the ``postgres`` user.
Tests skip where the binaries are missing, unless GISROADS_REQUIRE_QGIS is set (``make test``
and CI): then they fail.
"""
from __future__ import annotations

import getpass
import os
import shutil
import subprocess
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

PG_BIN = Path("/usr/lib/postgresql/15/bin")
POSTGIS_CONTROL = Path("/usr/share/postgresql/15/extension/postgis.control")
DATABASE = "gisroads"


@dataclass(frozen=True)
class Cluster:
    """A running cluster: its socket folder, port and superuser, and one PostGIS database."""

    socket_dir: Path
    port: int
    user: str

    @property
    def conninfo(self) -> str:
        """libpq key=value connection string (what GDAL's ``PG:`` and QGIS take)."""
        return f"dbname={DATABASE} host={self.socket_dir} port={self.port} user={self.user}"

    def gdal(self) -> str:
        """The database as a GDAL/OGR data source name."""
        return f"PG:{self.conninfo}"

    def qgis_layer(self, table: str) -> str:
        """A PostGIS table as a Processing input layer string."""
        return f'postgres://{self.conninfo} table="public"."{table}" (geom)'

    def qgis_sink(self, table: str) -> str:
        """A new PostGIS table as a Processing feature-sink destination."""
        return f'postgis:{self.conninfo} table="public"."{table}" (geom)'

    def sql(self, statement: str) -> str:
        """Run SQL through psql; returns its unaligned output."""
        done = subprocess.run([str(PG_BIN / "psql"), "-X", "-At", "-v", "ON_ERROR_STOP=1",
                               "-d", self.conninfo, "-c", statement],
                              capture_output=True, text=True, check=True)
        return done.stdout.strip()

    def load(self, source: Path, layer: str, table: str, *, fid: str = "gid") -> None:
        """Copy ``layer`` of a vector file into ``table`` with the system's ogr2ogr, keeping
        its feature ids as the primary key ``fid``."""
        subprocess.run(["ogr2ogr", "-f", "PostgreSQL", self.gdal(), str(source), layer,
                        "-nln", table, "-lco", "GEOMETRY_NAME=geom", "-lco", f"FID={fid}",
                        "-preserve_fid"], capture_output=True, text=True, check=True)


def _missing_requirement() -> str | None:
    if not (PG_BIN / "initdb").exists():
        return f"PostgreSQL binaries missing ({PG_BIN}): scripts/setup.sh apt installs them"
    if not POSTGIS_CONTROL.exists():
        return "PostGIS missing (Debian package postgis): scripts/setup.sh apt installs it"
    if shutil.which("ogr2ogr") is None:
        return "ogr2ogr missing (Debian package gdal-bin)"
    return None


def _free_port() -> int:
    """A TCP port number no local server uses. The cluster listens on no TCP port (only its
    socket file, named after the port, in its own folder); a free number keeps it apart from
    any other cluster all the same, should one point libpq at the same folder."""
    import socket
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextmanager
def throwaway_cluster():
    """Start a cluster, yield its :class:`Cluster`, stop it and delete its files.

    Skips (or fails under GISROADS_REQUIRE_QGIS) where PostgreSQL/PostGIS are not installed.
    """
    missing = _missing_requirement()
    if missing:
        if os.environ.get("GISROADS_REQUIRE_QGIS"):
            pytest.fail(missing)
        pytest.skip(missing)
    as_root = os.geteuid() == 0
    user = "postgres" if as_root else getpass.getuser()
    run_as = ["runuser", "-u", user, "--"] if as_root else []
    folder = Path(tempfile.mkdtemp(prefix="gisroads-pg-"))
    if as_root:
        shutil.chown(folder, user)
    data = folder / "data"
    port = _free_port()

    def run(*command):
        subprocess.run([*run_as, *command], capture_output=True, text=True, check=True,
                       cwd=folder)

    try:
        run(str(PG_BIN / "initdb"), "-D", str(data), "-U", user, "-A", "trust", "-E", "UTF8")
        run(str(PG_BIN / "pg_ctl"), "-D", str(data), "-l", str(folder / "server.log"), "-w",
            "-o", f"-k {folder} -p {port} -c listen_addresses=''", "start")
        cluster = Cluster(folder, port, user)
        subprocess.run([str(PG_BIN / "createdb"), "-h", str(folder), "-p", str(port), "-U",
                        user, DATABASE], check=True, capture_output=True)
        cluster.sql("CREATE EXTENSION postgis")
        yield cluster
    finally:
        if (data / "postmaster.pid").exists():
            run(str(PG_BIN / "pg_ctl"), "-D", str(data), "-m", "fast", "-w", "stop")
        shutil.rmtree(folder, ignore_errors=True)
