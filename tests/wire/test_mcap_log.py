"""MCAP monitor logs (skinet record --format mcap): round trip, unfinished files, bad content."""

from __future__ import annotations

import io

import pytest
from pydantic import BaseModel

from skinet.errors import SourceError
from skinet.wire import mcap_log
from skinet.wire.mcap_log import McapLogWriter, is_mcap, read_mcap


def _write(samples: dict[str, BaseModel], repeat: int = 1) -> bytes:
    out = io.BytesIO()
    writer = McapLogWriter(out)
    t = 1700000000.0
    for n in range(repeat):
        for name, message in sorted(samples.items()):
            writer.write(f"skinet/spot_arm/{name}", message, t + n)
    writer.finish()
    return out.getvalue()


def test_round_trip_of_every_message(samples: dict[str, BaseModel]) -> None:
    data = _write(samples)
    assert is_mcap(data) and not is_mcap(b'{"t": 1}')
    entries = read_mcap(io.BytesIO(data), "log.mcap")
    assert [(e.key, e.type, e.message) for e in entries] == [
        (f"skinet/spot_arm/{name}", name, message) for name, message in sorted(samples.items())]
    assert {e.t for e in entries} == {1700000000.0}


def test_unfinished_file_keeps_its_complete_chunks(samples: dict[str, BaseModel], monkeypatch) -> None:
    monkeypatch.setattr(mcap_log, "CHUNK_SIZE", 2048)
    data = _write(samples, repeat=20)
    warnings: list[str] = []
    entries = read_mcap(io.BytesIO(data[: len(data) // 2]), "cut.mcap", warnings.append)
    assert 0 < len(entries) < 20 * len(samples)
    assert [e.t for e in entries] == sorted(e.t for e in entries)
    assert len(warnings) == 1 and warnings[0].startswith(
        f"cut.mcap: warning: the MCAP file ends early (recorder stopped without finishing it?): read {len(entries)} "
        "messages")


@pytest.mark.parametrize("data", [b"", mcap_log.MAGIC, mcap_log.MAGIC + b"\x00" * 3])
def test_no_readable_message_is_an_error(data: bytes) -> None:
    with pytest.raises(SourceError, match=r"^bad.mcap: error: not a readable MCAP file after 0 messages: "):
        read_mcap(io.BytesIO(data), "bad.mcap")


def test_foreign_messages_are_errors() -> None:
    from mcap.writer import Writer

    out = io.BytesIO()
    w = Writer(out)
    w.start()
    foo = w.register_channel("k", "json", w.register_schema("Foo", "jsonschema", b"{}"))
    bad = w.register_channel("skinet/s/verdicts", "json", w.register_schema("Verdicts", "jsonschema", b"{}"))
    w.add_message(foo, log_time=1, data=b"{}", publish_time=1, sequence=1)
    w.add_message(bad, log_time=2, data=b'{"v": 1}', publish_time=2, sequence=2)
    w.finish()
    with pytest.raises(SourceError) as err:
        read_mcap(io.BytesIO(out.getvalue()), "f.mcap")
    lines = str(err.value).splitlines()
    assert lines[0].startswith("f.mcap: message 1 on k: error: unknown message type 'Foo' (types: CanonicalEvent, ")
    assert lines[1] == "f.mcap: message 2 on skinet/s/verdicts: error: invalid Verdicts: system: Field required"
