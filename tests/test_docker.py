"""docker/: the compose file validates, and the images install sray exactly as the Makefile does.

No Docker engine exists here, so images are not built. Debian's ``docker-compose`` (1.29) checks a
compose file without an engine; set-up installs it (as root, through apt-get) when it is missing,
or the compose tests skip with the reason.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml
from packaging.requirements import Requirement

REPO = Path(__file__).resolve().parents[1]
DOCKER = REPO / "docker"
COMPOSE = DOCKER / "compose.yml"
SRAY_IMAGES = ("Dockerfile.cpu", "Dockerfile.cuda")


# ------------------------------------------------------------------------------- compose
@pytest.fixture(scope="module")
def compose_cli() -> str:
    """Path of ``docker-compose``, installed with apt-get if missing and possible; else skip."""
    found = shutil.which("docker-compose")
    if found:
        return found
    if os.geteuid() != 0 or not shutil.which("apt-get"):
        pytest.skip("docker-compose is missing and cannot be installed (needs root and apt-get)")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "install", "-y", "-q", "docker-compose"],
                ["sh", "-c", "apt-get update -q && apt-get install -y -q docker-compose"]):
        try:
            subprocess.run(cmd, env=env, capture_output=True, timeout=240, check=False)
        except subprocess.TimeoutExpired:
            pytest.skip(f"installing docker-compose timed out ({' '.join(cmd)})")
        found = shutil.which("docker-compose")
        if found:
            return found
    pytest.skip("docker-compose could not be installed with apt-get (no package lists or no network)")


def _config(cli: str, compose: Path, token: str | None = "test-token", *extra: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("RAY_AUTH_TOKEN", "RAY_CPU_WORKERS")}
    if token is not None:
        env["RAY_AUTH_TOKEN"] = token
    return subprocess.run([cli, "-f", str(compose), *extra, "config"], env=env, capture_output=True,
                          text=True, timeout=60)


def test_compose_file_validates_and_wires_the_cluster(compose_cli):
    result = _config(compose_cli, COMPOSE, "test-token", "--profile", "gpu")
    assert result.returncode == 0, result.stderr
    services = yaml.safe_load(result.stdout)["services"]
    assert set(services) == {"postgres", "mlflow", "ray-head", "ray-worker", "ray-gpu-worker"}

    mlflow = services["mlflow"]
    command = " ".join(mlflow["command"])
    assert "--backend-store-uri=postgresql://mlflow:" in command and "@postgres:5432/mlflow" in command
    assert "--artifacts-destination=/mlartifacts" in command and "--workers=1" in command
    assert re.search(r"--allowed-hosts=\S*mlflow", command)
    assert mlflow["environment"]["MLFLOW_SERVER_ENABLE_JOB_EXECUTION"] == "false"
    assert any(v.startswith("mlflow-artifacts:/mlartifacts") for v in mlflow["volumes"])
    assert mlflow["depends_on"]["postgres"]["condition"] == "service_healthy"

    for name in ("ray-head", "ray-worker", "ray-gpu-worker"):
        ray = services[name]
        size = ray["shm_size"]
        assert re.fullmatch(r"\d+gb", str(size)) and int(str(size)[:-2]) >= 1, f"{name}: shm_size {size}"
        assert ray["environment"]["RAY_AUTH_TOKEN"] == "test-token"
        assert ray["environment"]["MLFLOW_TRACKING_URI"] == "http://mlflow:5000"
        assert any(v.startswith("ray-storage:/storage") for v in ray["volumes"])
    assert "--head" in services["ray-head"]["command"]
    assert "--address=ray-head:6379" in services["ray-worker"]["command"]
    assert services["ray-worker"]["deploy"]["replicas"] == 2
    devices = services["ray-gpu-worker"]["deploy"]["resources"]["reservations"]["devices"]
    assert devices[0]["driver"] == "nvidia" and services["ray-gpu-worker"]["build"]["dockerfile"].endswith("cuda")


def test_compose_requires_the_shared_ray_token(compose_cli):
    result = _config(compose_cli, COMPOSE, token=None)
    assert result.returncode != 0 and "RAY_AUTH_TOKEN" in result.stderr


def test_validator_rejects_a_broken_file(compose_cli, tmp_path):
    broken = tmp_path / "compose.yml"
    broken.write_text(COMPOSE.read_text().replace("shm_size:", "shm_sise:", 1))
    result = _config(compose_cli, broken)
    assert result.returncode != 0 and "shm_sise" in result.stderr


# ---------------------------------------------------------------------------- Dockerfiles
def _makefile_setup_commands() -> tuple[list[str], dict[str, str]]:
    """The README's install recipe: the venv + pip commands of the Makefile's sray target."""
    text = (REPO / "Makefile").read_text()
    variables = {m[1]: m[2].strip() for m in re.finditer(r"^(?:export\s+)?(\w+)\s*[?:]?=\s*(.*)$", text, re.M)}
    variables["CURDIR"] = "<repo>"

    def expand(line: str) -> str:
        for _ in range(3):
            line = re.sub(r"\$\((\w+)\)", lambda m: variables.get(m[1], m[0]), line)
        return line

    recipe = re.search(r"^\$\(BIN\)/sray:.*\n((?:\t.*\n)+)", text, re.M)
    assert recipe, "Makefile: no `$(BIN)/sray:` recipe found"
    commands = [expand(line.strip()) for line in recipe[1].splitlines()]
    steps = [c.replace(".venv/bin/", "") for c in commands if " -m venv " in c or "pip install" in c]
    return steps, {k: expand(v) for k, v in variables.items()}


def _dockerfile(name: str) -> tuple[list[str], dict[str, str], list[str]]:
    """(shell commands of RUN lines, ENV values, COPY sources in order) of one Dockerfile."""
    text = re.sub(r"\\\n", " ", (DOCKER / name).read_text())
    runs, env, copies = [], {}, []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("RUN "):
            runs += [c.strip() for c in line[4:].split("&&")]
        elif line.startswith("ENV "):
            env.update(dict(re.findall(r"(\w+)=(\S+)", line)))
        elif line.startswith("COPY "):
            copies.append(line.split()[1])
        elif line.startswith("WORKDIR "):
            env["<workdir>"] = line.split()[1]
    return runs, env, copies


@pytest.mark.parametrize("name", SRAY_IMAGES)
def test_images_install_sray_like_the_makefile(name):
    make_steps, make_vars = _makefile_setup_commands()
    runs, env, copies = _dockerfile(name)
    index_url = '${TORCH_INDEX_URL:+--index-url "$TORCH_INDEX_URL"}'
    docker_steps = [" ".join(c.replace(".venv/bin/", "").replace(index_url, "").split())
                    for c in runs if " -m venv " in c or "pip install" in c]
    assert docker_steps == make_steps, f"{name} installs differently from the Makefile"
    assert make_vars["PIP_CONSTRAINT"] == "<repo>/constraints.txt"
    assert env["PIP_CONSTRAINT"] == f"{env['<workdir>']}/constraints.txt"
    assert copies[0] == "constraints.txt", f"{name}: constraints.txt must be in place before the first pip install"
    assert env["PATH"].startswith(f"{env['<workdir>']}/.venv/bin:")


def test_constraints_admit_the_cpu_and_cuda_torch_builds():
    pins = [Requirement(line) for line in (REPO / "constraints.txt").read_text().splitlines()
            if line.strip() and not line.startswith("#")]
    torch_pin = next(r for r in pins if r.name == "torch")
    for build in ("2.13.0", "2.13.0+cpu", "2.13.0+cu128", "2.13.0+cu130"):
        assert torch_pin.specifier.contains(build), build
    assert not torch_pin.specifier.contains("2.15.0")
    cpu_text = (DOCKER / "Dockerfile.cpu").read_text()
    assert "ARG TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu" in cpu_text
    assert "ARG TORCH_INDEX_URL=\n" in (DOCKER / "Dockerfile.cuda").read_text()  # PyPI's Linux wheel is CUDA


def test_mlflow_image_uses_the_pinned_mlflow_and_a_postgres_driver():
    runs, env, copies = _dockerfile("Dockerfile.mlflow")
    assert env["PIP_CONSTRAINT"] == f"{env['<workdir>']}/constraints.txt" and copies == ["constraints.txt"]
    install = next(c for c in runs if "mlflow" in c)
    assert "psycopg2-binary" in install and env["MLFLOW_SERVER_ENABLE_JOB_EXECUTION"] == "false"
