"""The wire protocol: message round trips, every reject reason, forward compatibility, Zenoh keys."""

import math

import msgpack
import numpy as np
import pytest

from protocol import keys
from protocol.messages import (
    ALLOWED_DTYPES,
    PROTOCOL_VERSION,
    REJECT_REASONS,
    ActorHello,
    DecodeError,
    EpisodeStats,
    GradientPush,
    LearnerStatus,
    Weights,
    check_shapes,
    decode,
    encode,
    pack_tensor,
)

# -- helpers ------------------------------------------------------------------------------------


def envelope(body, type_="weights", v=PROTOCOL_VERSION) -> bytes:
    """A hand-built payload, for what ``encode`` would refuse to produce."""
    return msgpack.packb({"v": v, "type": type_, "body": body}, use_bin_type=True)


def raw_tensor(dtype="float32", shape=(2,), data=None) -> dict:
    if data is None:
        data = np.zeros(shape, dtype=dtype).tobytes() if dtype in ALLOWED_DTYPES else b"\0" * 16
    return {"dtype": dtype, "shape": list(shape), "data": data}


def weights_body(**overrides) -> dict:
    body = {"version": 3, "sigma": 0.5, "tensors": {"w": raw_tensor()}, "run_id": "run"}
    body.update(overrides)
    return body


def gradient_body(**overrides) -> dict:
    body = {
        "actor_id": "actor-1", "base_version": 2, "agent_steps": 40, "tensors": {"w": raw_tensor()},
        "episodes": [episode_dict()], "loss_policy_acc": 0.1, "loss_policy_sa": 0.2,
        "loss_value_acc": 0.3, "loss_value_sa": 0.4,
    }
    body.update(overrides)
    return body


def hello_body(**overrides) -> dict:
    body = {"actor_id": "actor-1", "scenario": "cross", "host": "box", "pid": 123, "agent_steps": 7, "episodes": 2}
    body.update(overrides)
    return body


def episode_dict(**overrides) -> dict:
    ep = {"scenario": "cross", "lane": "north", "sign": "stop", "end_reason": "goal", "steps": 12,
          "mean_speed_mps": 4.5, "return_acc": 1.25, "return_sa": -0.5, "turn": "left"}
    ep.update(overrides)
    return ep


def rejected(payload, **kwargs) -> str:
    with pytest.raises(DecodeError) as info:
        decode(payload, **kwargs)
    return info.value.reason


def assert_tensors_equal(got: dict, want: dict) -> None:
    assert set(got) == set(want)
    for name, array in want.items():
        assert isinstance(got[name], np.ndarray)
        assert got[name].dtype == array.dtype, name
        assert got[name].shape == array.shape, name
        np.testing.assert_array_equal(got[name], array)


def sample_tensors() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return {
        "f32": rng.standard_normal((3, 4)).astype(np.float32),
        "f16": rng.standard_normal((5,)).astype(np.float16),
        "i64": np.array([[-(2**62), 0, 2**62 - 1]], dtype=np.int64),
        "u8": np.arange(256, dtype=np.uint8).reshape(16, 16),
        "empty": np.zeros((0,), dtype=np.float32),
        "empty_i64": np.zeros((0,), dtype=np.int64),
        "empty_2d": np.zeros((0, 3), dtype=np.float16),
    }


# -- (1) round trips ----------------------------------------------------------------------------


def test_weights_round_trip():
    tensors = sample_tensors()
    msg = Weights(version=17, sigma=0.25, tensors=tensors, run_id="exp-3")
    out = decode(encode(msg), expect=Weights)
    assert type(out) is Weights
    assert out.version == 17 and isinstance(out.version, int)
    assert out.sigma == 0.25 and isinstance(out.sigma, float)
    assert out.run_id == "exp-3"
    assert_tensors_equal(out.tensors, tensors)


def test_weights_round_trip_defaults_and_no_tensors():
    out = decode(encode(Weights(version=0, sigma=1)))
    assert out == Weights(version=0, sigma=1.0)
    assert out.tensors == {} and out.run_id == ""
    assert isinstance(out.sigma, float)  # an int on the wire for a float field comes back as float


def test_gradient_push_round_trip_with_several_episodes():
    tensors = sample_tensors()
    episodes = (
        EpisodeStats("cross", "north", "none", "goal", 100, 7.5, 3.25, 2.0, "left"),
        EpisodeStats("tee", "east", "yield", "crash", 3, 0.0, -10.0, -1.5),
        EpisodeStats("cross", "south", "stop", "horizon", 2000, 12.125, 0.0, 0.5, "straight"),
    )
    msg = GradientPush(actor_id="host.a_1-0", base_version=41, agent_steps=2103, tensors=tensors,
                       episodes=episodes, loss_policy_acc=-0.5, loss_policy_sa=1.5,
                       loss_value_acc=2.25, loss_value_sa=3.0)
    out = decode(encode(msg), expect=GradientPush)
    assert type(out) is GradientPush
    assert out.actor_id == "host.a_1-0"
    assert out.base_version == 41
    assert out.agent_steps == 2103
    assert out.loss_policy_acc == -0.5
    assert out.loss_policy_sa == 1.5
    assert out.loss_value_acc == 2.25
    assert out.loss_value_sa == 3.0
    assert isinstance(out.episodes, tuple)
    assert out.episodes == episodes
    assert all(type(e) is EpisodeStats for e in out.episodes)
    assert out.episodes[1].turn == ""
    assert_tensors_equal(out.tensors, tensors)


def test_gradient_push_round_trip_no_episodes():
    msg = GradientPush(actor_id="a", base_version=0, agent_steps=0)
    out = decode(encode(msg))
    assert out.episodes == () and out.tensors == {}
    assert (out.loss_policy_acc, out.loss_policy_sa, out.loss_value_acc, out.loss_value_sa) == (0.0,) * 4


def test_learner_status_round_trip_with_reach_by_scenario():
    msg = LearnerStatus(run_id="r", version=3, agent_steps=100, episodes=7, reach_rate=0.5, mean_speed_mps=7.5,
                        agent_steps_per_s=12.0, sigma=0.4, live_actors=2, rejected=0,
                        reach_by_scenario={"hard": 0.75, "hard-yield-drill": 0.25})
    assert decode(encode(msg), expect=LearnerStatus) == msg
    older = {k: v for k, v in msg.__dict__.items() if k != "reach_by_scenario"}  # a learner before the field
    assert decode(envelope(older, "status"), expect=LearnerStatus).reach_by_scenario == {}
    for bad in ([0.5], {"hard": "0.5"}):
        assert rejected(envelope({**older, "reach_by_scenario": bad}, "status")) == "schema"
    assert rejected(envelope({**older, "reach_by_scenario": {"hard": math.nan}}, "status")) == "non_finite"


def test_actor_hello_round_trip():
    msg = ActorHello(actor_id="actor-7", scenario="roundabout", host="node12", pid=4242,
                     agent_steps=123456, episodes=89)
    out = decode(encode(msg), expect=ActorHello)
    assert out == msg
    assert type(out) is ActorHello
    assert decode(encode(ActorHello("a", "s", "h", 1))) == ActorHello("a", "s", "h", 1, 0, 0)


@pytest.mark.parametrize("dtype", ALLOWED_DTYPES)
def test_each_allowed_dtype_round_trips_including_empty(dtype):
    values = np.arange(12).reshape(3, 4).astype(dtype)
    for array in (values, np.zeros((0,), dtype=dtype)):
        out = decode(encode(Weights(version=1, sigma=0.1, tensors={"t": array}))).tensors["t"]
        assert out.dtype == np.dtype(dtype)
        assert out.shape == array.shape
        np.testing.assert_array_equal(out, array)


def test_big_endian_and_non_contiguous_inputs_round_trip():
    big = np.arange(6, dtype=">f4").reshape(2, 3)
    strided = np.arange(20, dtype=np.int64).reshape(4, 5)[:, ::2]
    out = decode(encode(Weights(version=1, sigma=0.1, tensors={"big": big, "strided": strided}))).tensors
    assert out["big"].dtype == np.float32 and out["big"].dtype.isnative
    np.testing.assert_array_equal(out["big"], big)
    np.testing.assert_array_equal(out["strided"], strided)
    # on the wire the bytes are little-endian whatever the sender's byte order
    assert pack_tensor(big)["data"] == np.arange(6, dtype="<f4").tobytes()


def test_zero_dim_tensor_decodes_from_empty_shape():
    # the decoder handles shape [] (a 0-d tensor) ...
    out = decode(envelope(weights_body(tensors={"s": raw_tensor("float32", (), np.float32(2.5).tobytes())})))
    assert out.tensors["s"].shape == () and out.tensors["s"] == np.float32(2.5)


def test_zero_dim_tensor_round_trips():
    # ... but the encoder turns shape () into [1]
    scalar = np.array(2.5, dtype=np.float32)
    out = decode(encode(Weights(version=1, sigma=0.1, tensors={"s": scalar}))).tensors["s"]
    assert out.shape == ()
    assert out == scalar


def test_encode_refuses_disallowed_dtypes():
    for dtype in (np.float64, object, bool):
        with pytest.raises(ValueError):
            encode(Weights(version=1, sigma=0.1, tensors={"t": np.zeros(2, dtype=dtype)}))


def test_decode_accepts_bytearray_and_memoryview():
    payload = encode(ActorHello("a", "s", "h", 1))
    assert decode(bytearray(payload)) == ActorHello("a", "s", "h", 1)
    assert decode(memoryview(payload)) == ActorHello("a", "s", "h", 1)


# -- (2) every reject reason --------------------------------------------------------------------


def test_reject_reasons_are_all_covered_here():
    covered = {"oversize", "malformed", "version", "type", "schema", "dtype", "shape", "non_finite"}
    assert set(REJECT_REASONS) - covered == {"stale", "views"}  # the learner's calls, not the codec's


def test_oversize():
    payload = encode(Weights(version=1, sigma=0.1, tensors={"w": np.zeros(100, np.float32)}))
    assert rejected(payload, max_bytes=len(payload) - 1) == "oversize"
    assert decode(payload, max_bytes=len(payload)).version == 1  # exactly at the limit is fine


@pytest.mark.parametrize("payload", [
    pytest.param(bytes(np.random.default_rng(1).integers(0, 256, 64, dtype=np.uint8)), id="random-bytes"),
    pytest.param(b"\xc1", id="never-used-byte"),
    pytest.param(b"", id="empty"),
    pytest.param(encode(ActorHello("a", "s", "h", 1))[:-3], id="truncated"),
    pytest.param(encode(ActorHello("a", "s", "h", 1)) + b"\x00", id="trailing-data"),
    pytest.param(msgpack.packb([PROTOCOL_VERSION, "hello", {}]), id="list-not-map"),
    pytest.param(msgpack.packb("hello"), id="string"),
    pytest.param(msgpack.packb({"v": 1, "type": "hello"}), id="no-body"),
    pytest.param(msgpack.packb({"v": 1, "type": "hello", "body": {}, "extra": 1}), id="extra-envelope-key"),
    pytest.param(msgpack.packb({1: 1, "type": "hello", "body": {}}), id="non-string-map-key"),
])
def test_malformed(payload):
    assert rejected(payload) == "malformed"


def test_random_bytes_never_escape_as_other_errors():
    rng = np.random.default_rng(2)
    for _ in range(200):
        payload = bytes(rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8))
        try:
            decode(payload)
        except DecodeError as error:
            assert error.reason in REJECT_REASONS


@pytest.mark.parametrize("v", [99, 0, 2, "1", None])
def test_version(v):
    assert rejected(envelope(hello_body(), "hello", v=v)) == "version"


@pytest.mark.parametrize("type_", ["nonsense", "", "Weights", 1, None])
def test_unknown_type(type_):
    assert rejected(envelope(weights_body(), type_)) == "type"


def test_unexpected_type():
    payload = encode(GradientPush(actor_id="a", base_version=0, agent_steps=1))
    assert rejected(payload, expect=Weights) == "type"
    assert rejected(encode(ActorHello("a", "s", "h", 1)), expect=GradientPush) == "type"
    assert isinstance(decode(payload, expect=GradientPush), GradientPush)


@pytest.mark.parametrize("payload", [
    pytest.param(envelope({"sigma": 0.5}), id="weights-missing-version"),
    pytest.param(envelope({"version": 1}), id="weights-missing-sigma"),
    pytest.param(envelope(weights_body(version="3")), id="version-as-string"),
    pytest.param(envelope(weights_body(version=3.0)), id="version-as-float"),
    pytest.param(envelope(weights_body(version=True)), id="version-as-bool"),
    pytest.param(envelope(weights_body(sigma="0.5")), id="sigma-as-string"),
    pytest.param(envelope(weights_body(sigma=False)), id="sigma-as-bool"),
    pytest.param(envelope(weights_body(run_id=5)), id="run-id-as-int"),
    pytest.param(envelope(weights_body(tensors=[raw_tensor()])), id="tensors-as-list"),
    pytest.param(envelope(weights_body(tensors={"w": [1, 2]})), id="tensor-not-a-map"),
    pytest.param(envelope(weights_body(tensors={"w": {"dtype": "float32", "shape": [1]}})), id="tensor-no-data"),
    pytest.param(envelope(weights_body(tensors={"w": {**raw_tensor(), "order": "C"}})), id="tensor-extra-key"),
    pytest.param(envelope(weights_body(tensors={"w": raw_tensor(data="\0" * 8)})), id="tensor-data-as-str"),
    pytest.param(envelope([1, 2]), id="body-not-a-map"),
    pytest.param(envelope(gradient_body(episodes={"a": 1}), "gradient"), id="episodes-not-a-list"),
    pytest.param(envelope(gradient_body(episodes=[[1, 2]]), "gradient"), id="episode-not-a-map"),
    pytest.param(envelope(gradient_body(episodes=[{k: v for k, v in episode_dict().items() if k != "steps"}]),
                          "gradient"), id="episode-missing-steps"),
    pytest.param(envelope(gradient_body(episodes=[episode_dict(steps=1.5)]), "gradient"), id="episode-steps-float"),
    pytest.param(envelope({k: v for k, v in gradient_body().items() if k != "actor_id"}, "gradient"),
                 id="gradient-missing-actor-id"),
    pytest.param(envelope(hello_body(pid="1"), "hello"), id="hello-pid-as-string"),
    pytest.param(envelope(hello_body(episodes=[]), "hello"), id="hello-episodes-as-list"),
])
def test_schema(payload):
    assert rejected(payload) == "schema"


def test_schema_non_string_tensor_name():
    payload = envelope(weights_body(tensors={b"w": raw_tensor()}))
    assert rejected(payload) == "schema"


@pytest.mark.parametrize("dtype", ["object", "float64", "bool", "int32", "<f4", "O", 7, None])
def test_dtype(dtype):
    tensor = {"dtype": dtype, "shape": [2], "data": b"\0" * 16}
    assert rejected(envelope(weights_body(tensors={"w": tensor}))) == "dtype"
    assert rejected(envelope(gradient_body(tensors={"w": tensor}), "gradient")) == "dtype"


@pytest.mark.parametrize("tensor", [
    pytest.param(raw_tensor("float32", (3,), b"\0" * 8), id="too-few-bytes"),
    pytest.param(raw_tensor("float32", (2,), b"\0" * 12), id="too-many-bytes"),
    pytest.param(raw_tensor("float16", (2, 2), b"\0" * 6), id="f16-mismatch"),
    pytest.param(raw_tensor("int64", (0,), b"\0" * 8), id="bytes-for-empty"),
    pytest.param(raw_tensor("uint8", (4,), b"\0" * 3), id="u8-mismatch"),
    pytest.param({"dtype": "float32", "shape": [-1], "data": b"\0" * 4}, id="negative-dim"),
    pytest.param({"dtype": "float32", "shape": [1.0], "data": b"\0" * 4}, id="float-dim"),
    pytest.param({"dtype": "float32", "shape": [True], "data": b"\0" * 4}, id="bool-dim"),
    pytest.param({"dtype": "float32", "shape": 1, "data": b"\0" * 4}, id="shape-not-a-list"),
    pytest.param({"dtype": "float32", "shape": "1", "data": b"\0" * 4}, id="shape-as-string"),
])
def test_shape_from_bytes(tensor):
    assert rejected(envelope(weights_body(tensors={"w": tensor}))) == "shape"


@pytest.mark.parametrize("shape, data", [
    pytest.param([1] * 100, b"\0" * 4, id="100-dims"),
    pytest.param([0, 2**63], b"", id="dim-beyond-intp"),
    pytest.param([2**40, 2**40, 2**40, 0], b"", id="overflowing-product-times-zero"),
])
def test_shape_numpy_cannot_build(shape, data):
    tensor = {"dtype": "float32", "shape": shape, "data": data}
    assert rejected(envelope(weights_body(tensors={"w": tensor}))) == "shape"


def test_check_shapes():
    tensors = {"a": np.zeros((2, 3), np.float32), "b": np.zeros((4,), np.float32)}
    check_shapes(tensors, {"a": (2, 3), "b": (4,)}, "weights")  # matches: no error
    check_shapes(tensors, {"a": [2, 3], "b": [4]}, "weights")  # lists are as good as tuples
    bad = [
        {"a": (2, 3)},  # an unexpected tensor
        {"a": (2, 3), "b": (4,), "c": (1,)},  # a missing tensor
        {"a": (2, 3), "c": (4,)},  # a renamed tensor
        {"a": (3, 2), "b": (4,)},  # transposed
        {"a": (2, 3), "b": (4, 1)},  # an extra dimension
        {"a": (2, 3), "b": (5,)},  # a different length
    ]
    for expected in bad:
        with pytest.raises(DecodeError) as info:
            check_shapes(tensors, expected, "weights")
        assert info.value.reason == "shape", expected


def test_check_shapes_on_decoded_message():
    msg = decode(encode(GradientPush(actor_id="a", base_version=0, agent_steps=1,
                                     tensors={"w": np.zeros((2, 2), np.float32)})))
    check_shapes(msg.tensors, {"w": (2, 2)}, "gradient")
    with pytest.raises(DecodeError) as info:
        check_shapes(msg.tensors, {"w": (4,)}, "gradient")
    assert info.value.reason == "shape"


@pytest.mark.parametrize("dtype, bad", [
    ("float32", np.nan), ("float32", np.inf), ("float32", -np.inf), ("float16", np.nan), ("float16", np.inf),
])
def test_non_finite_tensor(dtype, bad):
    array = np.array([1.0, bad, 2.0], dtype=dtype)
    # encode() does not check values, so this payload is what a buggy actor would really send
    payload = encode(GradientPush(actor_id="a", base_version=0, agent_steps=1, tensors={"g": array}))
    assert rejected(payload) == "non_finite"
    assert rejected(envelope(weights_body(tensors={"w": pack_tensor(array)}))) == "non_finite"


@pytest.mark.parametrize("payload", [
    pytest.param(envelope(weights_body(sigma=math.inf)), id="sigma-inf"),
    pytest.param(envelope(weights_body(sigma=-math.inf)), id="sigma-minus-inf"),
    pytest.param(envelope(weights_body(sigma=math.nan)), id="sigma-nan"),
    pytest.param(envelope(gradient_body(loss_value_sa=math.nan), "gradient"), id="loss-nan"),
    pytest.param(envelope(gradient_body(loss_policy_acc=math.inf), "gradient"), id="loss-inf"),
    pytest.param(envelope(gradient_body(episodes=[episode_dict(), episode_dict(return_sa=math.inf)]), "gradient"),
                 id="episode-return-inf"),
    pytest.param(envelope(gradient_body(episodes=[episode_dict(mean_speed_mps=math.nan)]), "gradient"),
                 id="episode-speed-nan"),
])
def test_non_finite_number(payload):
    assert rejected(payload) == "non_finite"


def test_integer_tensors_are_not_checked_for_finiteness():
    big = np.array([np.iinfo(np.int64).max, np.iinfo(np.int64).min], dtype=np.int64)
    out = decode(envelope(weights_body(tensors={"w": pack_tensor(big)})))
    np.testing.assert_array_equal(out.tensors["w"], big)


# -- (3) decoded tensors are writable copies ----------------------------------------------------


def test_decoded_tensors_are_writable_copies():
    tensors = sample_tensors()
    payload = encode(Weights(version=1, sigma=0.1, tensors=tensors))
    snapshot = bytes(payload)
    out = decode(payload)
    for name, array in out.tensors.items():
        assert array.flags.writeable, name
        assert not np.shares_memory(array, np.frombuffer(payload, np.uint8))  # not a view on the payload
        array[...] = 0  # must not raise
        array += 1
    assert payload == snapshot  # the payload itself is untouched
    again = decode(payload)
    assert_tensors_equal(again.tensors, tensors)  # a fresh decode still sees the original values


def test_decoded_tensors_do_not_share_memory_with_each_other():
    msg = Weights(version=1, sigma=0.1, tensors={"a": np.ones(4, np.float32), "b": np.ones(4, np.float32)})
    out = decode(encode(msg))
    out.tensors["a"][:] = 5
    np.testing.assert_array_equal(out.tensors["b"], np.ones(4, np.float32))


# -- (4) forward compatibility ------------------------------------------------------------------


def test_unknown_body_fields_are_ignored():
    out = decode(envelope(weights_body(from_the_future=[1, 2, {"x": b"y"}], another=None)))
    assert isinstance(out, Weights) and out.version == 3 and out.run_id == "run"
    out = decode(envelope(hello_body(gpu="h100"), "hello"))
    assert out == ActorHello("actor-1", "cross", "box", 123, 7, 2)
    out = decode(envelope(gradient_body(episodes=[episode_dict(weather="rain")], priority=3), "gradient"))
    assert out.episodes[0] == EpisodeStats("cross", "north", "stop", "goal", 12, 4.5, 1.25, -0.5, "left")


@pytest.mark.parametrize("missing, default", [
    ("loss_value_sa", 0.0), ("loss_value_acc", 0.0), ("loss_policy_acc", 0.0), ("loss_policy_sa", 0.0),
    ("episodes", ()), ("tensors", {}),
])
def test_gradient_push_missing_defaulted_field(missing, default):
    body = {k: v for k, v in gradient_body().items() if k != missing}
    out = decode(envelope(body, "gradient"), expect=GradientPush)
    assert getattr(out, missing) == default
    assert out.actor_id == "actor-1" and out.base_version == 2 and out.agent_steps == 40


def test_other_missing_defaulted_fields():
    out = decode(envelope({"version": 5, "sigma": 0.2}))
    assert out == Weights(version=5, sigma=0.2)
    out = decode(envelope({"actor_id": "a", "scenario": "s", "host": "h", "pid": 9}, "hello"))
    assert out == ActorHello("a", "s", "h", 9, agent_steps=0, episodes=0)
    ep = {k: v for k, v in episode_dict().items() if k != "turn"}
    out = decode(envelope(gradient_body(episodes=[ep]), "gradient"))
    assert out.episodes[0].turn == ""


def test_missing_defaults_are_not_shared_between_messages():
    a = decode(envelope({"version": 1, "sigma": 0.2}))
    b = decode(envelope({"version": 2, "sigma": 0.2}))
    assert a.tensors is not b.tensors


# -- (5) keys -----------------------------------------------------------------------------------


def test_keys_documented_strings():
    assert keys.weights("run1") == "crossway/run1/weights"
    assert keys.weights_version("run1") == "crossway/run1/weights/version"
    assert keys.gradients("run1") == "crossway/run1/gradients"
    assert keys.hello("run1", "actor-3") == "crossway/run1/hello/actor-3"
    assert keys.hello_all("run1") == "crossway/run1/hello/*"
    assert keys.actor_token("run1", "actor-3") == "crossway/run1/actors/actor-3"
    assert keys.actor_tokens("run1") == "crossway/run1/actors/*"
    assert keys.weights("A.b_c-9") == "crossway/A.b_c-9/weights"


def test_actor_id_from_key():
    assert keys.actor_id_from_key(keys.hello("r", "host.a_1")) == "host.a_1"
    assert keys.actor_id_from_key(keys.actor_token("r", "x-2")) == "x-2"


RUN_FUNCS = [keys.weights, keys.weights_version, keys.gradients, keys.hello_all, keys.actor_tokens,
             lambda run: keys.hello(run, "ok"), lambda run: keys.actor_token(run, "ok")]
BAD_NAMES = ["a/b", "/a", "a/", "*", "a*", "**", "a b", " a", "a ", "", "a\tb", "a$b", "a?b", "a#b"]


@pytest.mark.parametrize("bad", BAD_NAMES)
def test_keys_reject_bad_run_names(bad):
    for func in RUN_FUNCS:
        with pytest.raises(ValueError):
            func(bad)


@pytest.mark.parametrize("bad", BAD_NAMES)
def test_keys_reject_bad_actor_ids(bad):
    with pytest.raises(ValueError):
        keys.hello("run", bad)
    with pytest.raises(ValueError):
        keys.actor_token("run", bad)


def test_keys_reject_trailing_newline():
    with pytest.raises(ValueError):
        keys.weights("run\n")
    with pytest.raises(ValueError):
        keys.hello("run", "actor\n")


def test_the_view_square_travels_with_weights_and_gradients_and_defaults_to_unsaid():
    weights = decode(encode(Weights(version=3, sigma=0.1, view_extent_m=70.0, view_shift_m=15.0)))
    assert (weights.view_extent_m, weights.view_shift_m) == (70.0, 15.0)
    push = decode(encode(GradientPush(actor_id="a", base_version=0, agent_steps=1, view_extent_m=50)))
    assert (push.view_extent_m, push.view_shift_m) == (50.0, 0.0)
    # a sender that predates the fields: 0 says "not said", which the learner does not check
    body = {"actor_id": "a", "base_version": 0, "agent_steps": 1}
    old = decode(msgpack.packb({"v": PROTOCOL_VERSION, "type": "gradient", "body": body}, use_bin_type=True))
    assert old.view_extent_m == 0.0
    with pytest.raises(DecodeError) as error:
        decode(encode(GradientPush(actor_id="a", base_version=0, agent_steps=1, view_extent_m=float("nan"))))
    assert error.value.reason == "non_finite"
