"""Goals and safe plans (docs/semantics.md §8): from a marking, the commands that reach a goal and never
let any property be violated, whatever the skills' outcomes.

Modules, in the order a question flows through them:

- :mod:`~skinet.plan.goal` (grammar ``goal.lark``), :mod:`~skinet.plan.inputs`,
  :mod:`~skinet.plan.goalfile`: the goal language, skill inputs, mission files;
- :mod:`~skinet.plan.arena`: the game on the stable graph, per component, and Safe;
- :mod:`~skinet.plan.solve`: strong, strong cyclic and weak fixpoints with their layers,
  over either :mod:`~skinet.plan.explicit` (the explored graph) or
  :mod:`~skinet.plan.symbolic` (BDDs of the whole product);
- :mod:`~skinet.plan.policy`: the plan, its policy, rank, steps and branches;
- :mod:`~skinet.plan.diagnose`: the reason of a ``none``;
- :mod:`~skinet.plan.planner`: :class:`Planner`, which puts them together.

Use from a pilot, which plans at every change of the live marking (the
goal-independent structures are built once per start marking and kept)::

    goal = parse_goal(system, "run spot:go_to_waypoint",
                      inputs={"go_to_waypoint": {"target": {"x": 12.0, "y": 3.5, "z": 0.0}}})
    # or: goals = parse_goals(text, system, "mission.toml")   (files: skinet.system.load.load_goals)
    planner = Planner(system, engine="auto", memory_limit=1 << 30)
    plan = planner.plan(goal, marking, budget=1.0)
    plan.answer            # "strong" | "cyclic" | "none" | "unknown"
    plan.moves             # strong: most moves any play takes; cyclic: fewest, outcomes favourable
    plan.reason            # why none or unknown (None for a plan)
    plan.retries           # outcomes after which the plan goes back to a step already taken
    plan.action(marking)   # Command(skillset, transition, inputs) | Wait() | Reached() | None
    plan.covers(marking), plan.rank(marking)
    plan.steps, plan.branches, plan.policy()
    planner.admissible(marking)   # the commands no outcome can turn into a violation (strict check)

``plan.action(m)`` answers for any marking ``m`` of the plan's winning region,
so the pilot reuses one plan while the live marking stays inside (an outcome
that came before a command took effect leaves it in Safe, docs/semantics.md §8, *Races*;
if it is still covered, the plan goes on); ``None`` means the marking left
the region (an event, the operator's own command, a model divergence): plan
again from there.  ``Reached()`` means a ``reach`` goal holds; a ``run`` goal is
reached by its outcome (``goal.target(skillset, transition)``).  Errors in goals
are :class:`skinet.errors.SourceError`; a marking the robot cannot be in
raises :class:`skinet.errors.SkinetError`.

Examples:
    >>> from skinet.system.load import load_system
    >>> system, _ = load_system("skillsets/spot_arm.toml")
    >>> plan = Planner(system).plan(parse_goal(system, "reach spot:Standing"))
    >>> plan.answer, plan.moves, plan.action(system.initial_marking())
    ('cyclic', 4, Command(skillset='spot', transition='init_power.start', inputs={}))
"""

from skinet.plan.goal import Goal, parse_goal
from skinet.plan.goalfile import parse_goals
from skinet.plan.planner import ENGINES, Planner
from skinet.plan.policy import Branch, Command, Plan, Reached, Step, Wait

__all__ = ["ENGINES", "Branch", "Command", "Goal", "Plan", "Planner", "Reached", "Step", "Wait", "parse_goal",
           "parse_goals"]
