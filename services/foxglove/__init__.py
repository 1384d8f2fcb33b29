"""The live Foxglove connection of a monitored system (docs/foxglove.md)."""
