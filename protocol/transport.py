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
        # start even when the other side is not up yet, and keep retrying a lost connection
        # (a restarted learner comes back on the same endpoint)
        config.insert_json5("connect/timeout_ms", "-1")
        config.insert_json5("connect/exit_on_failure", "false")
        config.insert_json5("transport/link/tx/queue/congestion_control/block/wait_before_close",
                            str(BLOCK_TIMEOUT_MS * 1000))  # [us]
        return config


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
