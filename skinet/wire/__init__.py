"""The language-neutral contract between services: keys, messages, codec (docs/semantics.md §1)."""
