"""Zenoh sessions for crossway: one place that turns endpoints and modes into a session.

Learners listen, actors connect; both may instead go through a Zenoh router. Multicast
scouting is off by default (it does not cross container bridges and tests must not depend on
the network around them), so every peer names its endpoints explicitly.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import zenoh

# Large messages (weights, gradients) must not be silently dropped under congestion; a link that
# stays blocked longer than this is closed (NOTES-transport.md) [ms]
BLOCK_TIMEOUT_MS = 20_000


class TransportError(RuntimeError):
    """The transport could not be opened or used; the message says what to check."""


@dataclass(frozen=True)
class TransportConfig:
    """Where a process's Zenoh session listens and connects."""

    mode: str = "peer"  # "peer", "client" (needs a router or a listening peer) or "router"
    listen: tuple[str, ...] = ()  # endpoints to listen on, e.g. ("tcp/0.0.0.0:7447",)
    connect: tuple[str, ...] = ()  # endpoints to connect to, e.g. ("tcp/10.0.0.5:7447",)
    multicast_scouting: bool = False
    # mutual TLS for tls/ endpoints (deploy/make-certs.sh makes a development set): every side
    # presents a certificate signed by ``tls_root_ca`` and refuses peers that cannot
    tls_root_ca: str = ""  # CA certificate (PEM) that signs every party's certificate
    tls_certificate: str = ""  # this process's certificate (PEM)
    tls_private_key: str = ""  # and its private key (PEM)

    def zenoh_config(self) -> zenoh.Config:
        if self.mode not in ("peer", "client", "router"):
            raise TransportError(f"mode must be peer, client or router, got {self.mode!r}")
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps(self.mode))
        config.insert_json5("scouting/multicast/enabled", json.dumps(self.multicast_scouting))
        if self.listen:
            config.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        if self.connect:
            config.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        if self.tls_root_ca or self.tls_certificate or self.tls_private_key:
            _insert_tls(self, config)
        elif any(e.startswith("tls/") for e in self.listen + self.connect):
            raise TransportError("tls/ endpoints need --tls-root-ca, --tls-cert and --tls-key")
        # start even when the other side is not up yet, and keep retrying a lost connection
        # (a restarted learner comes back on the same endpoint)
        config.insert_json5("connect/timeout_ms", "-1")
        config.insert_json5("connect/exit_on_failure", "false")
        config.insert_json5("transport/link/tx/queue/congestion_control/block/wait_before_close",
                            str(BLOCK_TIMEOUT_MS * 1000))  # [us]
        return config


def _check_files(config: TransportConfig) -> None:
    import os

    for label, path in (("root CA", config.tls_root_ca), ("certificate", config.tls_certificate),
                        ("private key", config.tls_private_key)):
        if not path:
            raise TransportError(f"TLS needs a {label} file as well (root CA, certificate and key)")
        if not os.path.isfile(path):
            raise TransportError(f"TLS {label} {path!r} is not a file")


def _tls_keys(config: TransportConfig) -> dict[str, str]:
    return {
        "root_ca_certificate": config.tls_root_ca,
        "listen_certificate": config.tls_certificate, "listen_private_key": config.tls_private_key,
        "connect_certificate": config.tls_certificate, "connect_private_key": config.tls_private_key,
    }


def _insert_tls(transport: TransportConfig, config: zenoh.Config) -> None:
    _check_files(transport)
    for key, value in _tls_keys(transport).items():
        config.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    config.insert_json5("transport/link/tls/enable_mtls", "true")  # both sides show certificates
    # only TLS links: a plain tcp/ peer cannot join a secured process
    if any(not e.startswith("tls/") for e in transport.listen + transport.connect):
        raise TransportError("with TLS every endpoint must be tls/HOST:PORT")
    config.insert_json5("transport/link/protocols", json.dumps(["tls"]))
    if not transport.listen:  # a peer listens on tcp/[::]:0 unless told otherwise
        config.insert_json5("listen/endpoints", "[]")


def open_session(config: TransportConfig) -> zenoh.Session:
    """Open a session or raise ``TransportError`` naming the endpoints."""
    try:
        return zenoh.open(config.zenoh_config())
    except zenoh.ZError as error:
        raise TransportError(
            f"could not open a Zenoh {config.mode} session (listen {list(config.listen)}, "
            f"connect {list(config.connect)}): {error}"
        ) from None


def parse_endpoints(text: str | None) -> tuple[str, ...]:
    """``"tcp/a:1,tcp/b:2"`` to a tuple; checks each has a protocol prefix."""
    if not text:
        return ()
    endpoints = tuple(e.strip() for e in text.split(",") if e.strip())
    for endpoint in endpoints:
        if "/" not in endpoint:
            raise ValueError(f"endpoint {endpoint!r} needs a protocol, e.g. tcp/{endpoint}")
    return endpoints
