"""PostgreSQL for the MLflow server: Debian's package (installed when missing and this process may), a database
folder of the cluster's own (``<dir>/pg``, its Unix socket inside), listening on 127.0.0.1 only, a password
(``scram-sha-256``) asked of every client. PostgreSQL refuses to run as root: as root, it runs as ``postgres``."""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import time
from pathlib import Path

from sray.platform.cluster.processes import ClusterError, ProcessRecord, port_open, spawn, wait_until

DB_USER = "sray"  # the database role MLflow logs in as (the superuser of the cluster's own database folder)
DB_NAME = "mlflow"  # the database holding MLflow's tables
SERVICE_USER = "postgres"  # the user PostgreSQL runs as when sray runs as root (created by Debian's package)


def bin_dir() -> Path | None:
    """The newest ``/usr/lib/postgresql/<version>/bin`` holding ``initdb``, or None."""
    found = sorted(Path("/usr/lib/postgresql").glob("*/bin/initdb"), key=lambda p: int(p.parts[-3])
                   if p.parts[-3].isdigit() else 0)
    return found[-1].parent if found else None


def ensure_installed(log_path: Path) -> Path:
    """PostgreSQL's binaries folder, installing Debian's package first when missing (root only)."""
    found = bin_dir()
    if found is not None:
        return found
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        raise ClusterError("PostgreSQL is not installed: run `sudo apt-get install -y postgresql` "
                           "(Debian/Ubuntu), then `sray cluster up` again")
    print("[cluster] installing PostgreSQL (apt-get install postgresql) ...", flush=True)
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    with open(log_path, "ab") as log:
        for cmd in (["apt-get", "update", "-q"], ["apt-get", "install", "-y", "-q", "postgresql"]):
            subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, check=False)
    found = bin_dir()
    if found is None:
        raise ClusterError(f"installing PostgreSQL with apt-get failed; see {log_path}, or install it by hand "
                           "(`apt-get install -y postgresql`)")
    return found


def _service_user() -> str | None:
    """``postgres`` when running as root (PostgreSQL refuses root), else None (run as ourselves)."""
    if os.geteuid() != 0:
        return None
    try:
        pwd.getpwnam(SERVICE_USER)
    except KeyError:
        raise ClusterError(f"running as root, PostgreSQL needs the user {SERVICE_USER!r}, which Debian's "
                           "postgresql package creates: run `apt-get install -y postgresql`") from None
    return SERVICE_USER


def init_db(bins: Path, data: Path, password: str, log_path: Path) -> None:
    """``initdb`` into ``data`` (unless done) with role :data:`DB_USER`, scram password auth; ClusterError naming the
    first folder above ``data`` that the service user cannot enter."""
    user = _service_user()
    for folder in reversed(data.parent.parents):
        if user and not folder.stat().st_mode & 0o001:
            raise ClusterError(f"{folder}: the {user!r} user PostgreSQL runs as cannot enter this folder; "
                               f"`chmod o+x {folder}` or pass a --dir elsewhere")
    if (data / "PG_VERSION").exists():
        return
    data.mkdir(parents=True, exist_ok=True)
    data.chmod(0o700)
    pwfile = data.parent / "pg.pw"
    pwfile.write_text(password + "\n")
    pwfile.chmod(0o600)
    if user:
        for path in (data, pwfile):
            shutil.chown(path, user, user)
    try:
        with open(log_path, "ab") as log:
            done = subprocess.run([str(bins / "initdb"), "-D", str(data), "-U", DB_USER, f"--pwfile={pwfile}",
                                   "--auth=scram-sha-256", "-E", "UTF8", "--no-instructions"],
                                  stdout=log, stderr=subprocess.STDOUT, user=user, group=user,
                                  extra_groups=[] if user else None, check=False)
    finally:
        pwfile.unlink(missing_ok=True)
    if done.returncode != 0:
        raise ClusterError(f"initdb into {data} failed; see {log_path}")


def start(bins: Path, data: Path, port: int, log_path: Path) -> ProcessRecord:
    """Start the server on 127.0.0.1:``port`` (socket in ``data``) and wait until it accepts connections."""
    user = _service_user()
    cmd = [str(bins / "postgres"), "-D", str(data), "-p", str(port), "-c", "listen_addresses=127.0.0.1",
           "-c", f"unix_socket_directories={data}", "-c", "max_connections=200"]
    record = spawn(cmd, log_path, user=user, cwd=data)
    wait_until(lambda: port_open("127.0.0.1", port), 60, "PostgreSQL", log_path, record)
    return record


def ensure_database(bins: Path, port: int, password: str) -> None:
    """Create :data:`DB_NAME` unless it exists (over TCP, with the password)."""
    env = {**os.environ, "PGPASSWORD": password}
    base = ["-h", "127.0.0.1", "-p", str(port), "-U", DB_USER]
    for _ in range(40):
        probe = subprocess.run([str(bins / "psql"), *base, "-d", "postgres", "-tAc",
                                f"SELECT 1 FROM pg_database WHERE datname = '{DB_NAME}'"],
                               capture_output=True, text=True, env=env, check=False)
        if probe.returncode == 0:
            break
        time.sleep(0.25)
    else:
        raise ClusterError(f"PostgreSQL on 127.0.0.1:{port} refused the login of {DB_USER!r}: {probe.stderr.strip()}")
    if probe.stdout.strip() == "1":
        return
    made = subprocess.run([str(bins / "createdb"), *base, DB_NAME], capture_output=True, text=True, env=env,
                          check=False)
    if made.returncode != 0:
        raise ClusterError(f"createdb {DB_NAME} failed: {made.stderr.strip()}")


def backend_uri(port: int) -> str:
    """The SQLAlchemy URI of the MLflow database, without the password (given as PGPASSWORD)."""
    return f"postgresql+psycopg2://{DB_USER}@127.0.0.1:{port}/{DB_NAME}"
