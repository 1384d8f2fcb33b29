"""The operator's live web dashboard (docs/semantics.md §7): a Zenoh observer, a small web server, and the goal box that
hands goals to the pilot (docs/semantics.md §8, :mod:`~services.dashboard.goalbox`)."""
