"""Numeric limits of the Zenoh contract (schemas/README.md), importable without pydantic.

``skinet_cli`` checks its options against them before anything heavy is imported.
"""

from __future__ import annotations

# The least exploration budget a predictor accepts, seconds: below it an answer could
# only be "undecided" everywhere, so a monitor refuses to start with a smaller one.
MIN_BUDGET = 0.05

# The largest time budget any command, service or request accepts, seconds: one day.
# Past it a deadline or a query timeout computed from the budget would mean "never"
# (1e308 seconds overflows the timers it is handed to), so it is refused, not clamped.
MAX_BUDGET = 86400.0

# The largest PredictRequest payload a predictor decodes, bytes.  A request carries the
# live marking only: the paper's system takes about 300 bytes, 8 corpus skillsets about
# 3 KB, so 64 KiB leaves room for a few hundred skillsets.
MAX_PREDICT_REQUEST = 1 << 16

# Seconds a skill the pilot started may run without an outcome before the pilot asks its
# manager for its status (a response lost while a link was down is then found); the
# pilot's --outcome-timeout.  The models give no skill a duration, so one bound serves all.
PILOT_OUTCOME_TIMEOUT = 60.0

# The rhythm of the views' rounds and of the monitor's feed (skinet/<system>/@feed, docs/foxglove.md): a round
# every FEED_ROUND seconds while results come, as a display refreshes; past FEED_STEPS steps in one round (500 a
# second: a robot makes a few) only the last result of each kind is kept, and while such a flood lasts the
# rounds come every FEED_FLOOD_ROUND seconds.
FEED_ROUND = 0.02
FEED_STEPS = 10
FEED_FLOOD_ROUND = 0.25
