"""Secured transport (mutual TLS) and the Zenoh router, over real sessions on loopback."""

import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh

from learner.service import LearnerService, LearnerServiceConfig
from protocol import keys
from protocol.messages import GradientPush, encode
from protocol.transport import TransportConfig, TransportError, open_session
from test_distributed import free_port, wait_for

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="making certificates needs openssl")


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    good = tmp_path_factory.mktemp("certs")
    evil = tmp_path_factory.mktemp("evil")
    for directory in (good, evil):
        subprocess.run(["bash", str(REPO / "deploy" / "make-certs.sh"), str(directory)], check=True,
                       capture_output=True)
    return good, evil


def tls(endpoint_key: str, endpoint: str, directory: Path, who: str, ca: Path | None = None) -> TransportConfig:
    return TransportConfig(**{endpoint_key: (endpoint,)}, tls_root_ca=str(ca or directory / "ca.pem"),
                           tls_certificate=str(directory / f"{who}.pem"), tls_private_key=str(directory / f"{who}.key"))


def test_mutual_tls_lets_actors_in_and_keeps_others_out(tmp_path, certs):
    good, evil = certs
    port = free_port()
    service = LearnerService(LearnerServiceConfig(
        run_dir=tmp_path, transport=tls("listen", f"tls/127.0.0.1:{port}", good, "learner"), metrics_port=0,
        checkpoint_interval_s=3600), log=lambda _: None)
    thread = threading.Thread(target=service.run, daemon=True)
    thread.start()
    actor = subprocess.Popen(
        [sys.executable, "-m", "crossway", "actor", "--connect", f"tls/localhost:{port}", "--id", "trusted",
         "--scenario", "easy", "--delay-max", "0.5", "--update-interval", "10", "--seed", "1",
         "--tls-root-ca", str(good / "ca.pem"), "--tls-cert", str(good / "actor.pem"),
         "--tls-key", str(good / "actor.key")],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: service.pushes_by_actor.get("trusted", 0) >= 2, 120, "the trusted actor's pushes")
        push = encode(GradientPush("intruder", service.core.version, 10,
                                   {n: np.zeros(s, np.float32) for n, s in service.core.shapes.items()}))
        intruders = {
            "plain tcp": TransportConfig(connect=(f"tcp/127.0.0.1:{port}",)),
            "another CA's certificate": tls("connect", f"tls/localhost:{port}", evil, "actor", ca=good / "ca.pem"),
        }
        for name, config in intruders.items():
            with open_session(config) as session:
                time.sleep(1.0)
                replies = [r for r in session.get(keys.weights("default"), timeout=2.0) if r.ok is not None]
                assert replies == [], f"{name} read the weights"
                for _ in range(3):
                    session.put(keys.gradients("default"), push, congestion_control=zenoh.CongestionControl.BLOCK)
                time.sleep(1.0)
        assert "intruder" not in service.pushes_by_actor
        assert service._rejected == 0  # nothing reached the learner to be refused
        assert "intruder" not in service._live_actors and "trusted" in service._live_actors
    finally:
        actor.send_signal(signal.SIGTERM)
        actor.wait(timeout=30)
        service.stop()
        thread.join(timeout=30)


def test_tls_needs_every_file_and_only_tls_endpoints(certs):
    good, _ = certs
    with pytest.raises(TransportError, match="need --tls-root-ca"):
        open_session(TransportConfig(listen=("tls/127.0.0.1:1",)))
    with pytest.raises(TransportError, match="private key"):
        open_session(TransportConfig(listen=("tls/127.0.0.1:1",), tls_root_ca=str(good / "ca.pem"),
                                     tls_certificate=str(good / "learner.pem")))
    with pytest.raises(TransportError, match="every endpoint must be tls"):
        open_session(tls("listen", "tcp/127.0.0.1:1", good, "learner"))


def test_learner_and_actor_meet_through_a_router(tmp_path):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen([sys.executable, "-m", "crossway", "router", "--listen", endpoint],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    service = LearnerService(LearnerServiceConfig(
        run_dir=tmp_path, transport=TransportConfig(mode="client", connect=(endpoint,)), metrics_port=0,
        checkpoint_interval_s=3600), log=lambda _: None)
    thread = threading.Thread(target=service.run, daemon=True)
    actor = None
    try:
        time.sleep(1.5)
        thread.start()
        actor = subprocess.Popen(
            [sys.executable, "-m", "crossway", "actor", "--mode", "client", "--connect", endpoint, "--id", "routed",
             "--scenario", "easy", "--delay-max", "0.5", "--update-interval", "10", "--seed", "2"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        wait_for(lambda: service.pushes_by_actor.get("routed", 0) >= 2, 120, "pushes through the router")
        assert "routed" in service._live_actors
    finally:
        if actor is not None:
            actor.send_signal(signal.SIGTERM)
            actor.wait(timeout=30)
        service.stop()
        thread.join(timeout=30)
        router.send_signal(signal.SIGTERM)
        _, err = router.communicate(timeout=30)
    assert router.returncode == 0 and "router: stopped" in err
