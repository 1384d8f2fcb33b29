"""The pilot (SPEC §8): goals in, safe commands out."""
