"""Zenoh key expressions: every topic crossway uses, in one place.

All keys live under ``crossway/<run>/`` so that several runs can share a router.

==============================  ===========  ===========================================================
key                             who          what
==============================  ===========  ===========================================================
crossway/<run>/weights          learner      queryable: replies with the newest ``Weights``;
                                             also published (rate-limited) when weights change
crossway/<run>/weights/version  learner      tiny publication of the newest version number (ASCII int)
crossway/<run>/gradients        actors       ``GradientPush`` messages (put, congestion control BLOCK)
crossway/<run>/hello/<actor>    actors       ``ActorHello`` heartbeats (put)
crossway/<run>/actors/<actor>   actors       liveliness token: present while the actor lives
crossway/<run>/status           learner      ``LearnerStatus`` about once a second
==============================  ===========  ===========================================================
"""

from __future__ import annotations

import re

ROOT = "crossway"
_SAFE = re.compile(r"[A-Za-z0-9_.-]+")


def _check(part: str, what: str) -> str:
    if not isinstance(part, str) or not _SAFE.fullmatch(part):
        raise ValueError(f"{what} {part!r} may only contain letters, digits, '_', '.', '-'")
    return part


def weights(run: str) -> str:
    return f"{ROOT}/{_check(run, 'run name')}/weights"


def weights_version(run: str) -> str:
    return f"{ROOT}/{_check(run, 'run name')}/weights/version"


def gradients(run: str) -> str:
    return f"{ROOT}/{_check(run, 'run name')}/gradients"


def hello(run: str, actor_id: str) -> str:
    return f"{ROOT}/{_check(run, 'run name')}/hello/{_check(actor_id, 'actor id')}"


def hello_all(run: str) -> str:
    return f"{ROOT}/{_check(run, 'run name')}/hello/*"


def actor_token(run: str, actor_id: str) -> str:
    return f"{ROOT}/{_check(run, 'run name')}/actors/{_check(actor_id, 'actor id')}"


def actor_tokens(run: str) -> str:
    return f"{ROOT}/{_check(run, 'run name')}/actors/*"


def status(run: str) -> str:
    return f"{ROOT}/{_check(run, 'run name')}/status"


def actor_id_from_key(key: str) -> str:
    """The last chunk of an actors/<id> or hello/<id> key."""
    return key.rsplit("/", 1)[-1]
