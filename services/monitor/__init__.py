"""The monitor service (docs/semantics.md §1): live marking, Algorithm 1, reports on Zenoh."""

from services.monitor.engine import Counters
from services.monitor.prediction import PredictorStats
from services.monitor.service import Monitor, MonitorView, start_monitor

__all__ = ["Counters", "Monitor", "MonitorView", "PredictorStats", "start_monitor"]
