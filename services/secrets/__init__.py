"""The compose job ``secrets``: makes what is missing in the vault and hands each service its own files."""
