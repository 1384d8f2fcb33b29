"""In-process chains of the services for the command line, the demos and the tests: the embedded run,
the whole chain, the pilot chain, watch, replays of logs and bundles (docs/how-it-works.md)."""
