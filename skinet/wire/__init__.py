"""The language-neutral contract between services: keys, messages, codec (SPEC §1)."""
