"""The operator's live web dashboard (SPEC §7): a read-only Zenoh observer and a small web server."""
