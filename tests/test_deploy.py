"""deploy/: the compose file, Prometheus and Grafana configuration, and a real Prometheus
server scraping a live learner (Debian's prometheus and docker-compose packages; ./dev test
installs them)."""

import json
import shutil
import socket
import subprocess
import threading
import time
import urllib.parse
import urllib.request
from pathlib import Path

import pytest

from learner.service import LearnerService, LearnerServiceConfig
from protocol.transport import TransportConfig

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
SERVICES = ("router", "learner", "actor", "prometheus", "grafana")
DASHBOARD_METRICS = ("crossway_reach_rate_ratio", "crossway_reach_rate_by_scenario_ratio", "crossway_episodes_total",
                     "crossway_agent_steps_per_second",
                     "crossway_weights_version", "crossway_gradient_staleness_versions_bucket",
                     "crossway_live_actors", "crossway_rejected_messages_total")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.skipif(shutil.which("docker-compose") is None, reason="needs Debian's docker-compose")
def test_compose_file_validates_and_names_every_service():
    result = subprocess.run(["docker-compose", "-f", str(DEPLOY / "docker-compose.yml"), "config", "--services"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert set(result.stdout.split()) == set(SERVICES)
    full = subprocess.run(["docker-compose", "-f", str(DEPLOY / "docker-compose.yml"), "config"],
                          capture_output=True, text=True, timeout=60)
    assert full.returncode == 0, full.stderr
    text = full.stdout
    assert "learner-runs:/runs" in text.replace(" ", "") or "source: learner-runs" in text  # named volume
    actor = text.split("\n  actor:\n", 1)[1].split("\n  grafana:\n", 1)[0]
    assert "ports" not in actor and "container_name" not in actor  # scales with --scale actor=N
    assert "tcp/router:7447" in actor


def test_prometheus_scrapes_the_learner_and_grafana_is_provisioned():
    scrape = (DEPLOY / "prometheus" / "prometheus.yml").read_text()
    assert "learner:9100" in scrape
    datasource = (DEPLOY / "grafana" / "provisioning" / "datasources" / "prometheus.yml").read_text()
    assert "url: http://prometheus:9090" in datasource and "uid: crossway-prometheus" in datasource
    dashboard = json.loads((DEPLOY / "grafana" / "dashboards" / "crossway.json").read_text())
    expressions = " ".join(t["expr"] for p in dashboard["panels"] for t in p["targets"])
    for metric in DASHBOARD_METRICS:
        assert metric in expressions, metric
    assert all(p["datasource"]["uid"] == "crossway-prometheus" for p in dashboard["panels"])


@pytest.fixture
def live_learner(tmp_path):
    port = free_port()
    service = LearnerService(LearnerServiceConfig(
        run_dir=tmp_path / "run", transport=TransportConfig(listen=(f"tcp/127.0.0.1:{free_port()}",)),
        metrics_port=port, metrics_address="127.0.0.1", checkpoint_interval_s=3600), log=lambda _: None)
    thread = threading.Thread(target=service.run, daemon=True)
    thread.start()
    time.sleep(1.0)
    yield service, port
    service.stop()
    thread.join(timeout=30)


@pytest.mark.skipif(shutil.which("promtool") is None, reason="needs Debian's prometheus (promtool)")
def test_promtool_accepts_the_learners_metrics(live_learner):
    _, port = live_learner
    text = urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=10).read()
    result = subprocess.run(["promtool", "check", "metrics"], input=text, capture_output=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.mark.skipif(shutil.which("prometheus") is None, reason="needs Debian's prometheus server")
def test_a_real_prometheus_reads_the_learners_metrics(live_learner, tmp_path):
    _, port = live_learner
    web = free_port()
    config = tmp_path / "prometheus.yml"
    config.write_text("global:\n  scrape_interval: 1s\nscrape_configs:\n  - job_name: crossway-learner\n"
                      f"    static_configs:\n      - targets: ['127.0.0.1:{port}']\n")
    server = subprocess.Popen(["prometheus", f"--config.file={config}", f"--storage.tsdb.path={tmp_path / 'tsdb'}",
                               f"--web.listen-address=127.0.0.1:{web}"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        query = urllib.parse.urlencode({"query": "crossway_weights_version"})
        deadline = time.monotonic() + 60
        found = []
        while time.monotonic() < deadline and not found:
            time.sleep(1.0)
            try:
                answer = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{web}/api/v1/query?{query}",
                                                           timeout=5).read())
            except OSError:
                continue
            found = answer["data"]["result"]
        assert found, "Prometheus never scraped the learner"
        assert found[0]["metric"]["job"] == "crossway-learner"
        assert float(found[0]["value"][1]) == 0.0
        rejected = urllib.parse.urlencode({"query": "crossway_rejected_messages_total"})
        answer = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{web}/api/v1/query?{rejected}", timeout=5).read())
        assert {r["metric"]["reason"] for r in answer["data"]["result"]} >= {"malformed", "stale", "shape"}
    finally:
        server.terminate()
        server.wait(timeout=30)


def test_compose_topology_as_processes_survives_a_learner_restart(tmp_path):
    """Router, learner and actor as in deploy/docker-compose.yml, but as plain processes."""
    import signal
    import sys

    from protocol import keys
    from protocol.messages import decode
    from protocol.transport import open_session

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    run_dir = tmp_path / "runs" / "easy"

    def crossway(*args):
        return subprocess.Popen([sys.executable, "-m", "crossway", *args], stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)

    def learner():
        return crossway("learner", "--mode", "client", "--connect", endpoint, "--listen", "", "--run-dir", str(run_dir),
                        "--metrics-port", "0", "--checkpoint-interval", "3600")

    router = crossway("router", "--listen", endpoint)
    time.sleep(1.5)
    first = learner()
    actor = crossway("actor", "--mode", "client", "--connect", endpoint, "--scenario", "easy", "--delay-max", "0.5",
                     "--update-interval", "10", "--seed", "3")
    statuses = []
    try:
        with open_session(TransportConfig(mode="client", connect=(endpoint,))) as session:
            session.declare_subscriber(keys.status("default"), lambda s: statuses.append(decode(s.payload.to_bytes())))
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not (statuses and statuses[-1].version >= 6):
                time.sleep(0.5)
            assert statuses and statuses[-1].version >= 6, "no training through the router"
            first.send_signal(signal.SIGTERM)
            _, log = first.communicate(timeout=60)
            stopped_at = int(log.rsplit("stopped at version ", 1)[1].split(";")[0])
            statuses.clear()
            second = learner()
            try:
                deadline = time.monotonic() + 120
                while time.monotonic() < deadline and not (statuses and statuses[-1].version >= stopped_at + 3):
                    time.sleep(0.5)
                assert statuses and statuses[-1].version >= stopped_at + 3, "no training after the restart"
                assert min(s.version for s in statuses) >= stopped_at
            finally:
                second.send_signal(signal.SIGTERM)
                _, log = second.communicate(timeout=60)
            assert f"at version {stopped_at}" in log
    finally:
        for process in (actor, first, router):
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
                process.wait(timeout=60)


def test_dockerfile_copies_what_exists_and_runs_crossway():
    root = DEPLOY.parent
    text = (root / "Dockerfile").read_text()
    sources = [line.split()[1] for line in text.splitlines() if line.startswith("COPY ") and "--from" not in line]
    for source in sources:
        assert (root / source).exists(), source
    packages = {"simcore", "algo", "protocol", "actors", "learner", "evaluation", "crossway"}
    assert packages <= set(sources)  # every package the console script needs
    assert 'ENTRYPOINT ["crossway"]' in text
    assert '"torch==2.13.0"' in text and "TORCH_INDEX_URL" in text  # CPU torch, index switchable
