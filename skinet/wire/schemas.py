"""JSON Schemas of the wire messages, generated from the pydantic models (docs/semantics.md §1).

``python -m skinet.wire.schemas [DIR]`` rewrites ``schemas/*.schema.json`` (default
``DIR``: the ``schemas/`` folder of the repository); ``tests/wire/test_schemas.py``
fails when the committed files drift from :func:`generate`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from skinet.wire.messages import MESSAGES

SUFFIX = ".schema.json"
DEFAULT_DIR = Path(__file__).resolve().parents[2] / "schemas"


DIALECT = "https://json-schema.org/draft/2020-12/schema"


def schema(model: type[BaseModel]) -> dict[str, Any]:
    """``model_json_schema()`` (validation mode) with ``v`` required, as the codec requires it."""
    out = model.model_json_schema()
    out["required"] = ["v", *(f for f in out.get("required", []) if f != "v")]
    return {"$schema": DIALECT, **out}


def generate() -> dict[str, str]:
    """File name -> JSON text: one ``<Message>.schema.json`` per message of ``MESSAGES``."""
    return {
        f"{name}{SUFFIX}": json.dumps(schema(model), indent=2, sort_keys=True, ensure_ascii=False) + "\n"
        for name, model in sorted(MESSAGES.items())
    }


def write(directory: Path) -> list[str]:
    """Write every schema into ``directory``, remove stale ones; returns the changed file names."""
    directory.mkdir(parents=True, exist_ok=True)
    wanted = generate()
    changed = []
    for stale in sorted(directory.glob(f"*{SUFFIX}")):
        if stale.name not in wanted:
            stale.unlink()
            changed.append(stale.name)
    for name, text in wanted.items():
        path = directory / name
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
            changed.append(name)
    return changed


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) > 1 or (args and args[0].startswith("-")):
        print("usage: python -m skinet.wire.schemas [DIR]   (default: the repository's schemas/)", file=sys.stderr)
        return 2
    directory = Path(args[0]) if args else DEFAULT_DIR
    changed = write(directory)
    print(f"{directory}: {len(changed)} file(s) changed" + (f" ({', '.join(changed)})" if changed else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
