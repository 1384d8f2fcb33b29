"""The committed JSON Schemas in ``schemas/`` match the pydantic models (docs/semantics.md §1)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import BaseModel

from skinet.wire import schemas
from skinet.wire.messages import MESSAGES

SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"
REGENERATE = "run `python -m skinet.wire.schemas` and commit schemas/"


def test_committed_schemas_match_models() -> None:
    generated = schemas.generate()
    committed = {p.name: p.read_text(encoding="utf-8") for p in SCHEMAS.glob(f"*{schemas.SUFFIX}")}
    missing = sorted(set(generated) - set(committed))
    stale = sorted(set(committed) - set(generated))
    differ = sorted(n for n in set(generated) & set(committed) if generated[n] != committed[n])
    assert not (missing or stale or differ), (
        f"schemas/ is out of date (missing: {missing}, stale: {stale}, different: {differ}); {REGENERATE}")


def test_one_schema_per_message() -> None:
    assert sorted(schemas.generate()) == sorted(f"{name}.schema.json" for name in MESSAGES)


def test_format_is_stable() -> None:
    for name, text in schemas.generate().items():
        assert text.endswith("}\n"), name
        assert text == json.dumps(json.loads(text), indent=2, sort_keys=True, ensure_ascii=False) + "\n", name


def test_version_is_required() -> None:
    for name, text in schemas.generate().items():
        schema = json.loads(text)
        assert schema["required"][0] == "v", name
        assert schema["properties"]["v"]["const"] == 1, name


def test_readme_names_every_schema() -> None:
    readme = (SCHEMAS / "README.md").read_text(encoding="utf-8")
    for name in schemas.generate():
        assert f"({name})" in readme, f"schemas/README.md does not link {name}"


def test_main_writes_and_removes_stale(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "Gone.schema.json").write_text("{}\n", encoding="utf-8")
    (tmp_path / "README.md").write_text("kept\n", encoding="utf-8")
    assert schemas.main([str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*schemas.generate(), "README.md"])
    assert f"{len(MESSAGES) + 1} file(s) changed" in capsys.readouterr().out
    assert schemas.main([str(tmp_path)]) == 0
    assert "0 file(s) changed" in capsys.readouterr().out


def test_samples_validate_against_schemas(samples: dict[str, BaseModel]) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    for name, text in schemas.generate().items():
        schema = json.loads(text)
        jsonschema.Draft202012Validator.check_schema(schema)
        message = samples[name.removesuffix(schemas.SUFFIX)]
        jsonschema.validate(message.model_dump(mode="json"), schema, cls=jsonschema.Draft202012Validator)
        without_v = {k: v for k, v in message.model_dump(mode="json").items() if k != "v"}
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(without_v, schema, cls=jsonschema.Draft202012Validator)


def test_readme_examples_are_valid_messages() -> None:
    """Every JSON example of schemas/README.md is a message the codec accepts, read back as written."""
    import json
    import re

    import msgpack

    from skinet.wire.codec import decode, encode
    from skinet.wire.messages import CheckReply, Divergences, Heartbeat

    readme = (SCHEMAS / "README.md").read_text(encoding="utf-8")
    examples = [json.loads(block) for block in re.findall(r"```json\n(.*?)```", readme, re.S)]
    kinds = [Heartbeat if "period" in e else Divergences if "entries" in e else CheckReply for e in examples]
    assert kinds == [Divergences, Heartbeat, CheckReply]
    def within(part: object, whole: object) -> bool:  # ``part`` as written, ``whole`` with the defaults too
        if isinstance(part, dict):
            return isinstance(whole, dict) and all(k in whole and within(v, whole[k]) for k, v in part.items())
        if isinstance(part, list):
            return isinstance(whole, list) and len(part) == len(whole) and all(map(within, part, whole))
        return part == whole

    for example, kind in zip(examples, kinds):
        assert within(example, msgpack.unpackb(encode(decode(msgpack.packb(example), kind))))
