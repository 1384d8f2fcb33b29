"""The supervised system: its model, loading it from disk, its prediction options, following it live."""
