"""The operator's live web dashboard (SPEC §7): a Zenoh observer, a small web server, and the goal box that
hands goals to the pilot (SPEC §8, :mod:`~services.dashboard.goalbox`)."""
