"""The predictor service: state-space exploration and mu1 over Zenoh (SPEC §1, §6)."""

from services.predictor.service import Predictor, start_predictor

__all__ = ["Predictor", "start_predictor"]
