"""The pilot on the core: run files with the outcomes a simulated robot gives, and a mission flown without Zenoh."""
