"""msgpack codec: round trips and one-line errors (docs/semantics.md §1, §7: bad input never crashes)."""

from __future__ import annotations

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.messages import MESSAGES, PredictRequest, StateSpaceReport


def test_samples_cover_every_message(samples: dict[str, BaseModel]) -> None:
    assert sorted(samples) == sorted(MESSAGES)


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_round_trip(samples: dict[str, BaseModel], name: str) -> None:
    message = samples[name]
    payload = encode(message)
    assert isinstance(payload, bytes)
    assert decode(payload, MESSAGES[name]) == message
    # the payload is plain msgpack of the JSON form, with the schema version
    data = msgpack.unpackb(payload)
    assert data == message.model_dump(mode="json")
    assert data["v"] == 1


def test_later_fields_are_left_out_at_their_default(samples: dict[str, BaseModel]) -> None:
    """A receiver that predates them (and rejects unknown fields) still reads a message that has nothing
    new to tell it; one that has, it refuses rather than misreads (schemas/README.md)."""
    for name, model in MESSAGES.items():
        later = getattr(model, "OMIT_AT_DEFAULT", ())
        if not later:
            continue
        plain = samples[name].model_copy(update={f: model.model_fields[f].get_default(call_default_factory=True)
                                                 for f in later})
        data = msgpack.unpackb(encode(plain))
        assert not set(later) & set(data), name
        assert decode(encode(plain), model) == plain
        assert set(later) <= set(msgpack.unpackb(encode(samples[name]))), name


def _payload(samples: dict[str, BaseModel], name: str, **changes: object) -> bytes:
    data = samples[name].model_dump(mode="json")
    for key, value in changes.items():
        if value is _DELETE:
            del data[key]
        else:
            data[key] = value
    return msgpack.packb(data)


_DELETE = object()


@pytest.mark.parametrize(
    ("payload", "error"),
    [
        (b"", "not msgpack: Unpack failed: incomplete input"),
        (b"garbage", "not msgpack: unpack(b) received extra data."),
        (b"\xc1", "not msgpack: FormatError"),  # the one byte msgpack never uses
        (b"\x92\x01", "not msgpack: Unpack failed: incomplete input"),
        (msgpack.packb([1, 2, 3]), "expected a map, got list"),
        (msgpack.packb("v"), "expected a map, got str"),
        (msgpack.packb({1: 2}), "not msgpack: int is not allowed for map key when strict_map_key=True"),
    ],
)
def test_garbage(payload: bytes, error: str) -> None:
    with pytest.raises(DecodeError) as info:
        decode(payload, PredictRequest)
    assert str(info.value) == error


@pytest.mark.parametrize(
    ("version", "error"),
    [
        (2, "unsupported schema version 2 (expected 1)"),
        (0, "unsupported schema version 0 (expected 1)"),
        ("1", "unsupported schema version '1' (expected 1)"),
        (True, "unsupported schema version True (expected 1)"),
        (1.0, "unsupported schema version 1.0 (expected 1)"),
        (None, "unsupported schema version None (expected 1)"),
        (_DELETE, "unsupported schema version None (expected 1)"),
    ],
)
def test_wrong_version(samples: dict[str, BaseModel], version: object, error: str) -> None:
    with pytest.raises(DecodeError) as info:
        decode(_payload(samples, "PredictRequest", v=version), PredictRequest)
    assert str(info.value) == error


@pytest.mark.parametrize(
    ("name", "changes", "error"),
    [
        ("PredictRequest", {"seq": _DELETE}, "invalid PredictRequest: seq: Field required"),
        ("PredictRequest", {"digest": _DELETE}, "invalid PredictRequest: digest: Field required"),
        ("PredictRequest", {"seq": -1}, "invalid PredictRequest: seq: Input should be greater than or equal to 0"),
        ("PredictRequest", {"budget": 0}, "invalid PredictRequest: budget: Input should be greater than or equal to 0.05"),
        ("PredictRequest", {"budget": 1e308}, "invalid PredictRequest: budget: Input should be less than or equal to 86400"),
        # Strict: no conversion of a string, a boolean or a float where the contract says otherwise (issue 25).
        ("PredictRequest", {"budget": "2.0"}, "invalid PredictRequest: budget: Input should be a valid number"),
        ("PredictRequest", {"seq": "3"}, "invalid PredictRequest: seq: Input should be a valid integer"),
        ("PredictRequest", {"skillsets": {"spot": {"resources": []}}},
         "invalid PredictRequest: skillsets.spot.resources: Input should be a valid dictionary"),
        ("PredictRequest", {"colour": "red"}, "invalid PredictRequest: colour: Extra inputs are not permitted"),
        ("StateSpaceReport", {"edges": "many"},
         "invalid StateSpaceReport: edges: Input should be a valid integer, unable to parse string as an integer"),
        ("CanonicalEvent", {"system": _DELETE}, "invalid CanonicalEvent: system: Field required"),
    ],
)
def test_invalid_fields(samples: dict[str, BaseModel], name: str, changes: dict, error: str) -> None:
    with pytest.raises(DecodeError) as info:
        decode(_payload(samples, name, **changes), MESSAGES[name])
    assert str(info.value) == error


def test_wrong_kind(samples: dict[str, BaseModel]) -> None:
    with pytest.raises(DecodeError, match=r"^invalid StateSpaceReport: "):
        decode(encode(samples["PredictRequest"]), StateSpaceReport)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64))
def test_arbitrary_bytes_only_raise_decode_error(payload: bytes) -> None:
    try:
        decode(payload, PredictRequest)
    except DecodeError as exc:
        assert "\n" not in str(exc)


_json = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.sampled_from(["v", "system", "digest", "seq", "skillsets", "budget", "x"]), _json))
def test_arbitrary_maps_only_raise_decode_error(data: dict) -> None:
    try:
        decode(msgpack.packb(data), PredictRequest)
    except DecodeError as exc:
        assert "\n" not in str(exc)
