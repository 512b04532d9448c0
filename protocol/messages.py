"""Every message actors and the learner exchange: typed, versioned schemas and their codec.

Encoding (MessagePack) is separate from the transport (Zenoh, ``protocol.transport``). A
message on the wire is a map ``{"v": PROTOCOL_VERSION, "type": TYPE, "body": {...}}``. Tensors
travel as ``{"dtype": "float32", "shape": [...], "data": <raw little-endian bytes>}``; object
dtypes never decode (that path would be pickle).

``decode`` validates everything before anything is used and raises ``DecodeError`` whose
``reason`` is one of ``REJECT_REASONS``; the learner counts those and keeps going. New fields
are appended with defaults, so older peers keep working (msgspec's schema-evolution rule).
"""

from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, field, fields
from typing import Any, ClassVar

import msgpack
import numpy as np

PROTOCOL_VERSION = 1
MAX_MESSAGE_BYTES = 256 * 1024 * 1024  # refuse anything larger before unpacking [bytes]
ALLOWED_DTYPES = ("float32", "float16", "int64", "uint8")
MAX_TENSOR_DIMS = 8

REJECT_REASONS = (
    "oversize",  # payload larger than the receiver's limit
    "malformed",  # not MessagePack, or not the envelope map
    "version",  # protocol version this receiver does not speak
    "type",  # unknown or unexpected message type
    "schema",  # a field missing or of the wrong type
    "dtype",  # a tensor dtype outside ALLOWED_DTYPES
    "shape",  # a tensor's bytes disagree with its shape, or shapes differ from the expected
    "non_finite",  # NaN or infinity in a float tensor or number
    "stale",  # computed on weights older than the learner accepts
    "views",  # from an actor whose agents see another view square than the run learns from
)


class DecodeError(ValueError):
    """A message was rejected; ``reason`` is one of REJECT_REASONS."""

    def __init__(self, reason: str, detail: str):
        assert reason in REJECT_REASONS, reason
        self.reason = reason
        super().__init__(f"{reason}: {detail}")


# -- tensors ------------------------------------------------------------------------------------


def pack_tensor(array: np.ndarray) -> dict[str, Any]:
    array = np.asarray(array)
    if not array.flags.c_contiguous:
        array = array.copy(order="C")  # (np.ascontiguousarray would turn a 0-d tensor into 1-d)
    if array.dtype.name not in ALLOWED_DTYPES:
        raise ValueError(f"dtype {array.dtype} cannot travel; allowed: {ALLOWED_DTYPES}")
    little_endian = array.astype(array.dtype.newbyteorder("<"), copy=False)
    return {"dtype": array.dtype.name, "shape": list(array.shape), "data": little_endian.tobytes()}


def unpack_tensor(raw: Any, where: str) -> np.ndarray:
    """Validate and rebuild a tensor; the result is a writable copy."""
    if not isinstance(raw, dict) or set(raw) != {"dtype", "shape", "data"}:
        raise DecodeError("schema", f"{where}: expected a tensor map with dtype, shape, data")
    dtype, shape, data = raw["dtype"], raw["shape"], raw["data"]
    if not isinstance(dtype, str) or dtype not in ALLOWED_DTYPES:
        raise DecodeError("dtype", f"{where}: dtype {dtype!r} not in {ALLOWED_DTYPES}")
    if (not isinstance(shape, list) or len(shape) > MAX_TENSOR_DIMS
            or not all(isinstance(d, int) and not isinstance(d, bool) and 0 <= d < 2**31 for d in shape)):
        raise DecodeError("shape", f"{where}: shape must be at most {MAX_TENSOR_DIMS} integers in "
                                   f"[0, 2^31), got {str(shape)[:80]}")
    if not isinstance(data, bytes):
        raise DecodeError("schema", f"{where}: data must be bytes")
    item = np.dtype(dtype).newbyteorder("<")
    expected = math.prod(shape) * item.itemsize
    if len(data) != expected:
        raise DecodeError("shape", f"{where}: {len(data)} bytes for shape {shape} of {dtype} (expected {expected})")
    array = np.frombuffer(data, dtype=item).reshape(shape).astype(np.dtype(dtype), copy=True)
    if array.dtype.kind == "f" and not np.isfinite(array).all():
        raise DecodeError("non_finite", f"{where}: NaN or infinity in tensor")
    return array


# -- schemas ------------------------------------------------------------------------------------
# Field annotations use these names; the decoder checks types by them.

_CHECKS = {
    "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "float": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
    "str": lambda v: isinstance(v, str),
    "bool": lambda v: isinstance(v, bool),
}


@dataclass(frozen=True)
class EpisodeStats:
    """One finished episode, reported with the gradient it produced."""

    scenario: str
    lane: str
    sign: str  # none, yield, stop
    end_reason: str  # goal, crash, off_path, time_over, sign_change, horizon
    steps: int
    mean_speed_mps: float
    return_acc: float
    return_sa: float
    turn: str = ""


@dataclass(frozen=True)
class Message:
    TYPE: ClassVar[str] = ""


@dataclass(frozen=True)
class Weights(Message):
    """The global network, published by the learner and served on request."""

    TYPE: ClassVar[str] = "weights"
    version: int  # number of updates applied so far
    sigma: float  # exploration standard deviation of the Gaussian policy at this version
    tensors: dict[str, np.ndarray] = field(default_factory=dict)
    run_id: str = ""
    # the view square these weights learn from (side, centre ahead of the car) [m], fixed by the
    # first gradient the run applied; 0: not fixed yet. An actor whose scenario shows another refuses them.
    view_extent_m: float = 0.0
    view_shift_m: float = 0.0


@dataclass(frozen=True)
class GradientPush(Message):
    """One agent's whole-episode gradient sum (D-A3C), tagged with its starting weights."""

    TYPE: ClassVar[str] = "gradient"
    actor_id: str
    base_version: int  # weights version the episode started from
    agent_steps: int  # simulator steps the episode took
    tensors: dict[str, np.ndarray] = field(default_factory=dict)
    episodes: tuple[EpisodeStats, ...] = ()
    loss_policy_acc: float = 0.0
    loss_policy_sa: float = 0.0
    loss_value_acc: float = 0.0
    loss_value_sa: float = 0.0
    # the view square of the actor's scenario (side, centre ahead of the car) [m]; 0: not said
    view_extent_m: float = 0.0
    view_shift_m: float = 0.0


@dataclass(frozen=True)
class ActorHello(Message):
    """An actor announces itself when it starts and with every heartbeat."""

    TYPE: ClassVar[str] = "hello"
    actor_id: str
    scenario: str
    host: str
    pid: int
    agent_steps: int = 0  # simulator agent-steps since the actor started
    episodes: int = 0


@dataclass(frozen=True)
class LearnerStatus(Message):
    """The learner's progress, published about once a second (progress lines, dashboards)."""

    TYPE: ClassVar[str] = "status"
    run_id: str
    version: int
    agent_steps: int  # behind every applied gradient
    episodes: int
    reach_rate: float  # goal fraction of the last episodes (0-1)
    mean_speed_mps: float
    agent_steps_per_s: float
    sigma: float
    live_actors: int
    rejected: int  # messages refused since start, any reason
    # goal fraction of the last episodes of each scenario label, e.g. {"hard": 0.8, "hard-yield-drill": 0.7}
    reach_by_scenario: dict[str, float] = field(default_factory=dict)


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.TYPE: cls for cls in (Weights, GradientPush, ActorHello, LearnerStatus)
}

_FIELD_KINDS = {
    "version": "int", "sigma": "float", "run_id": "str", "actor_id": "str", "base_version": "int",
    "agent_steps": "int", "loss_policy_acc": "float", "loss_policy_sa": "float",
    "loss_value_acc": "float", "loss_value_sa": "float", "scenario": "str", "host": "str",
    "pid": "int", "episodes_count": "int", "lane": "str", "sign": "str", "end_reason": "str",
    "steps": "int", "mean_speed_mps": "float", "return_acc": "float", "return_sa": "float",
    "turn": "str", "reach_rate": "float", "agent_steps_per_s": "float", "live_actors": "int",
    "rejected": "int", "view_extent_m": "float", "view_shift_m": "float",
}


def _body(message: Message) -> dict[str, Any]:
    body: dict[str, Any] = {}
    for f in fields(message):
        value = getattr(message, f.name)
        if f.name == "tensors":
            body[f.name] = {name: pack_tensor(t) for name, t in value.items()}
        elif f.name == "episodes" and isinstance(value, tuple):
            body[f.name] = [asdict(e) for e in value]
        else:
            body[f.name] = value
    return body


def encode(message: Message) -> bytes:
    """MessagePack bytes of a message, envelope included."""
    return msgpack.packb({"v": PROTOCOL_VERSION, "type": message.TYPE, "body": _body(message)}, use_bin_type=True)


def _check_scalar(name: str, value: Any, where: str) -> Any:
    kind = _FIELD_KINDS.get(name)
    if kind is None or not _CHECKS[kind](value):
        raise DecodeError("schema", f"{where}.{name}: expected {kind or 'a known field'}, got {type(value).__name__}")
    if kind == "float":
        if not math.isfinite(value):
            raise DecodeError("non_finite", f"{where}.{name}: {value}")
        return float(value)
    return value


def _build(cls: type, raw: dict[str, Any], where: str) -> Any:
    kwargs: dict[str, Any] = {}
    for f in fields(cls):
        if f.name not in raw:
            if f.default is not MISSING or f.default_factory is not MISSING:
                continue  # a field added after the sender's version: keep the default
            raise DecodeError("schema", f"{where}: missing field {f.name!r}")
        value = raw[f.name]
        if f.name == "tensors":
            if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
                raise DecodeError("schema", f"{where}.tensors: expected a map of name to tensor")
            kwargs[f.name] = {k: unpack_tensor(v, f"{where}.tensors[{k}]") for k, v in value.items()}
        elif f.name == "episodes" and cls is GradientPush:
            if not isinstance(value, list):
                raise DecodeError("schema", f"{where}.episodes: expected a list")
            episodes = []
            for i, item in enumerate(value):
                if not isinstance(item, dict):
                    raise DecodeError("schema", f"{where}.episodes[{i}]: expected a map")
                episodes.append(_build(EpisodeStats, item, f"{where}.episodes[{i}]"))
            kwargs[f.name] = tuple(episodes)
        elif f.name == "reach_by_scenario":
            if not isinstance(value, dict):
                raise DecodeError("schema", f"{where}.reach_by_scenario: expected a map of label to rate")
            kwargs[f.name] = {_check_scalar("scenario", k, f"{where}.reach_by_scenario"):
                              _check_scalar("reach_rate", v, f"{where}.reach_by_scenario[{k}]")
                              for k, v in value.items()}
        elif f.name == "episodes":  # ActorHello and LearnerStatus count episodes
            kwargs[f.name] = _check_scalar("episodes_count", value, where)
        else:
            kwargs[f.name] = _check_scalar(f.name, value, where)
    # fields this peer does not know (added by a newer peer) are ignored
    return cls(**kwargs)


def decode(payload: bytes | bytearray | memoryview, expect: type[Message] | None = None,
           max_bytes: int = MAX_MESSAGE_BYTES) -> Message:
    """Validate and decode one message; raise ``DecodeError`` with a counted reason."""
    if len(payload) > max_bytes:
        raise DecodeError("oversize", f"{len(payload)} bytes > limit {max_bytes}")
    try:
        raw = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=True, max_bin_len=max_bytes)
    except Exception as error:  # msgpack raises several types for corrupt input
        raise DecodeError("malformed", f"not MessagePack: {type(error).__name__}") from None
    if not isinstance(raw, dict) or set(raw) != {"v", "type", "body"}:
        raise DecodeError("malformed", "expected the envelope {v, type, body}")
    if not isinstance(raw["v"], int) or isinstance(raw["v"], bool) or raw["v"] != PROTOCOL_VERSION:
        raise DecodeError("version", f"protocol version {raw['v']!r}, this peer speaks {PROTOCOL_VERSION}")
    cls = MESSAGE_TYPES.get(raw["type"]) if isinstance(raw["type"], str) else None
    if cls is None:
        raise DecodeError("type", f"unknown message type {raw['type']!r}")
    if expect is not None and cls is not expect:
        raise DecodeError("type", f"expected {expect.TYPE!r}, got {cls.TYPE!r}")
    if not isinstance(raw["body"], dict):
        raise DecodeError("schema", f"{cls.TYPE}: body must be a map")
    return _build(cls, raw["body"], cls.TYPE)


def check_shapes(tensors: dict[str, np.ndarray], expected: dict[str, tuple[int, ...]], where: str) -> None:
    """Raise ``DecodeError('shape')`` unless names and shapes match the receiver's network."""
    if set(tensors) != set(expected):
        missing = sorted(set(expected) - set(tensors))
        extra = sorted(set(tensors) - set(expected))
        raise DecodeError("shape", f"{where}: tensor names differ (missing {missing[:3]}, unexpected {extra[:3]})")
    for name, array in tensors.items():
        if tuple(array.shape) != tuple(expected[name]):
            raise DecodeError("shape", f"{where}.{name}: shape {tuple(array.shape)}, expected {tuple(expected[name])}")
