"""Static checks of a parsed skillset model (docs/semantics.md §2, "Validation").

Errors: unknown resource or state in an expression or effect, duplicate names,
undeclared initial state, transitions from or to undeclared states, an
expression whose disjunctive normal form (one transition per clause, docs/semantics.md §3)
exceeds :data:`MAX_CLAUSES`, an element whose transition variants exceed
:data:`MAX_VARIANTS`.
Warnings: duplicate transition pairs or type declarations, undeclared types of
data, parameters, inputs, outputs and progress fields (real files have them, see
``corpus/EXPECTED.md``), an unsatisfiable postcondition (docs/semantics.md §3).  Each
diagnostic points at the offending name.  Cost: linear in the model, plus the
DNF of each expression (bounded by MAX_CLAUSES).
"""

from __future__ import annotations

from collections.abc import Iterable

from skinet.errors import Diagnostic, Pos
from skinet.lang.dnf import TooManyClauses, dnf
from skinet.lang.expr import And, Const, Expr, Not, StateAtom, atoms
from skinet.lang.model import Effect, Model, Resource, Skill, Skillset, Variable

__all__ = ["validate", "sort_diagnostics", "MAX_CLAUSES", "MAX_VARIANTS"]

# Most clauses one guard, precondition set or postcondition may have in DNF: each
# clause is at least one transition, and real models have a handful.
MAX_CLAUSES = 1024
# Most transition variants one event, start, invariant, interrupt or mode may give
# (one per guard clause, postcondition clause and combination of the source states
# of the resources it moves, docs/semantics.md §3); the corpus needs at most a few dozen.
MAX_VARIANTS = 4096


def sort_diagnostics(diagnostics: Iterable[Diagnostic]) -> list[Diagnostic]:
    """Diagnostics by position (stable; those without a position last)."""

    def key(d: Diagnostic) -> tuple[int, int, int]:
        if d.pos is None:
            return (1, 0, 0)
        return (0, d.pos.line, d.pos.column)

    return sorted(diagnostics, key=key)


def validate(model: Model) -> list[Diagnostic]:
    """Every error and warning about ``model`` (docs/semantics.md §2), sorted by position."""
    checker = _Checker(model.source)
    checker.check_model(model)
    return sort_diagnostics(checker.diagnostics)


def _at(pos: Pos | None) -> str:
    return f"{pos.line}:{pos.column}" if pos is not None else "?"


class _Checker:
    def __init__(self, source: str) -> None:
        self.source = source
        self.diagnostics: list[Diagnostic] = []
        self.resources: dict[str, Resource] = {}
        self.states: dict[str, tuple[str, ...]] = {}

    def error(self, pos: Pos | None, message: str) -> None:
        self.diagnostics.append(Diagnostic(self.source, pos, "error", message))

    def warning(self, pos: Pos | None, message: str) -> None:
        self.diagnostics.append(Diagnostic(self.source, pos, "warning", message))

    def unique(
        self,
        entries: Iterable[tuple[str, Pos | None]],
        kind: str,
        scope: str = "",
        level: str = "error",
    ) -> None:
        """Report each name declared twice, at the second declaration."""
        seen: dict[str, Pos | None] = {}
        for name, pos in entries:
            if name in seen:
                what = f"{kind} '{name}'" if name else f"unnamed {kind}"
                message = f"duplicate {what}{scope} (first declared at {_at(seen[name])})"
                if level == "error":
                    self.error(pos, message)
                else:
                    self.warning(pos, message)
            else:
                seen[name] = pos

    # ---- model and skillset ---------------------------------------------------

    def check_model(self, model: Model) -> None:
        self.unique(((t.name, t.pos) for t in model.types), "type", level="warning")
        self.unique(((s.name, s.pos) for s in model.skillsets), "skillset")
        for skillset in model.skillsets:
            self.check_skillset(skillset)

    def check_skillset(self, ss: Skillset) -> None:
        known_types = {t.name for t in ss.types} | set(ss.type_params)
        self.resources = {}
        for r in ss.resources:
            self.resources.setdefault(r.name, r)
        self.states = {name: r.states for name, r in self.resources.items()}

        self.unique(((p.name, p.pos) for p in ss.parameters), "parameter")
        self.check_types(ss.parameters, known_types, "parameter", "")

        self.unique(((d.name, d.pos) for d in ss.data), "data")
        self.check_types(ss.data, known_types, "data", "")

        self.unique(((r.name, r.pos) for r in ss.resources), "resource")
        for r in ss.resources:
            self.check_resource(r)

        self.unique(((e.name, e.pos) for e in ss.events), "event")
        for e in ss.events:
            guard: list[dict[str, str]] | None = [{}]
            if e.guard is not None and self.check_expr(e.guard, f"guard of event '{e.name}'"):
                guard = self.clauses(e.guard, f"guard of event '{e.name}'", e.pos)
            if self.check_effects(e.effects, f"event '{e.name}'", f"effect of event '{e.name}'"):
                self.variants(f"event '{e.name}'", e.pos, guard, e.effects, None)

        self.unique(((s.name, s.pos) for s in ss.skills), "skill")
        for s in ss.skills:
            self.check_skill(s, known_types)

    def check_types(
        self, variables: Iterable[Variable], known: set[str], kind: str, owner: str
    ) -> None:
        for v in variables:
            if v.type not in known:
                self.warning(v.type_pos, f"unknown type '{v.type}' of {kind} '{v.name}'{owner}")

    # ---- resources ------------------------------------------------------------

    def check_resource(self, r: Resource) -> None:
        state_pos = r.state_pos or (None,) * len(r.states)
        self.unique(zip(r.states, state_pos), "state", f" in resource '{r.name}'")
        states = set(r.states)
        if r.initial and r.initial not in states:
            self.error(
                r.initial_pos,
                f"initial state '{r.initial}' of resource '{r.name}' is not declared",
            )
        if r.transitions is None:
            return
        n = len(r.transitions)
        sources = r.transition_pos or (None,) * n
        targets = r.transition_target_pos or sources
        for (a, b), pa, pb in zip(r.transitions, sources, targets):
            if a not in states:
                self.error(pa, f"transition from undeclared state '{a}' of resource '{r.name}'")
            if b not in states:
                self.error(pb, f"transition to undeclared state '{b}' of resource '{r.name}'")
        self.unique(
            ((f"{a} -> {b}", p) for (a, b), p in zip(r.transitions, sources)),
            "transition",
            f" in resource '{r.name}'",
            level="warning",
        )

    # ---- skills ---------------------------------------------------------------

    def check_skill(self, s: Skill, known_types: set[str]) -> None:
        of = f" of skill '{s.name}'"
        scope = f" in skill '{s.name}'"
        self.unique(((v.name, v.pos) for v in s.parameters), "parameter", scope)
        self.check_types(s.parameters, known_types, "parameter", of)
        self.unique(((v.name, v.pos) for v in s.inputs), "input", scope)
        self.unique(((v.name, v.pos) for v in s.outputs), "output", scope)
        self.check_types(s.inputs, known_types, "input", of)
        self.check_types(s.outputs, known_types, "output", of)

        self.unique(((p.name, p.pos) for p in s.preconditions), "precondition", scope)
        valid = [self.check_expr(p.expr, f"precondition '{p.name}'{of}") for p in s.preconditions]
        guard: list[dict[str, str]] | None = [{}]
        if s.preconditions and all(valid):
            conjunction: Expr = Const(True)
            for p in s.preconditions:
                conjunction = And(conjunction, p.expr)
            guard = self.clauses(conjunction, f"preconditions{of}", s.preconditions[0].pos)

        if self.check_effects(s.start, f"start{of}", f"start{of}"):
            self.variants(f"start{of}", s.pos, guard, s.start, None)

        self.unique(((i.name, i.pos) for i in s.invariants), "invariant", scope)
        for i in s.invariants:
            owner = f"invariant '{i.name}'{of}"
            violated: list[dict[str, str]] | None = None
            if self.check_expr(i.guard, f"guard of {owner}"):
                violated = self.clauses(Not(i.guard), f"guard of {owner}", i.pos)
            if self.check_effects(i.effects, owner, f"effect of {owner}"):
                self.variants(owner, i.pos, violated, i.effects, None)

        if s.progress is not None:
            fields = s.progress.fields
            self.unique(((v.name, v.pos) for v in fields), "progress field", scope)
            self.check_types(fields, known_types, "progress field", of)

        owner = f"interrupt{of}"
        effects_ok = self.check_effects(s.interrupt.effects, owner, f"effect of {owner}")
        post = self.check_postcondition(s.interrupt.postcondition, owner, s.interrupt.pos)
        if effects_ok:
            self.variants(owner, s.interrupt.pos or s.pos, [{}], s.interrupt.effects, post)

        # Named modes share one namespace; an unnamed one is unique per kind
        # (its transition is k.success or k.failure).
        self.unique(((m.name, m.pos) for m in s.modes if m.name), "mode", scope)
        for kind in ("success", "failure"):
            self.unique((("", m.pos) for m in s.modes if not m.name and m.kind == kind), kind, scope)
        for m in s.modes:
            owner = (f"{m.kind} '{m.name}'" if m.name else f"unnamed {m.kind}") + of
            effects_ok = self.check_effects(m.effects, owner, f"effect of {owner}")
            post = self.check_postcondition(m.postcondition, owner, m.pos)
            if effects_ok:
                self.variants(owner, m.pos, [{}], m.effects, post)

    # ---- expressions and effects ------------------------------------------------

    def check_state(self, resource: Resource, state: str, pos: Pos | None, where: str) -> None:
        if state not in resource.states:
            states = ", ".join(resource.states)
            self.error(
                pos,
                f"unknown state '{state}' of resource '{resource.name}'"
                f" (states: {states}) in {where}",
            )

    def check_expr(self, expr: Expr, where: str) -> bool:
        """Report unknown resources and states; True when there was none."""
        before = len(self.diagnostics)
        for atom in atoms(expr):
            if not isinstance(atom, StateAtom):
                continue
            resource = self.resources.get(atom.resource)
            if resource is None:
                self.error(atom.pos, f"unknown resource '{atom.resource}' in {where}")
            else:
                self.check_state(resource, atom.state, atom.state_pos, where)
        return len(self.diagnostics) == before

    def clauses(self, expr: Expr, where: str, pos: Pos | None) -> list[dict[str, str]] | None:
        """The DNF of a valid ``expr``, or None (and an error) when it is too large."""
        try:
            return dnf(expr, self.states, MAX_CLAUSES)
        except TooManyClauses:
            self.error(
                getattr(expr, "pos", None) or pos,
                f"{where} is too complex: more than {MAX_CLAUSES} clauses in disjunctive normal form"
                " (each clause becomes a transition)",
            )
            return None

    def check_postcondition(self, expr: Expr | None, owner: str, pos: Pos | None) -> list[dict[str, str]] | None:
        """Errors of a postcondition, and a warning when nothing can satisfy it (docs/semantics.md §3).

        Returns its clauses (``None`` when there is no postcondition or it is invalid).
        """
        if expr is None:
            return None
        where = f"postcondition of {owner}"
        if not self.check_expr(expr, where):
            return None
        clauses = self.clauses(expr, where, pos)
        if clauses == []:
            self.warning(
                getattr(expr, "pos", None) or pos,
                f"{where} is unsatisfiable: it moves no resource when the skill stops",
            )
        return clauses

    def variants(
        self,
        owner: str,
        pos: Pos | None,
        guard: list[dict[str, str]] | None,
        effects: Iterable[Effect],
        post: list[dict[str, str]] | None,
    ) -> None:
        """An error when ``owner`` would give more than MAX_VARIANTS transitions (docs/semantics.md §3).

        Each guard clause and postcondition clause gives one variant per
        combination of source states of the resources moved and not fixed by
        the guard clause.  Cost: O(MAX_VARIANTS) at most (the count stops early).
        """
        if guard is None:  # invalid or too complex: already reported
            return
        moved_by_effects = {e.resource for e in effects}
        count = 0
        for clause in guard:
            for post_clause in post or [{}]:
                n = 1
                for r in moved_by_effects | set(post_clause):
                    if r not in clause:
                        n *= len(self.states[r])
                count += n
                if count > MAX_VARIANTS:
                    self.error(
                        pos,
                        f"{owner} is too large: more than {MAX_VARIANTS} transition variants"
                        " (one per guard clause and combination of source states of the resources it moves)",
                    )
                    return

    def check_effects(self, effects: Iterable[Effect], owner: str, where: str) -> bool:
        """Report effects on unknown resources or states; True when there was none."""
        before = len(self.diagnostics)
        for e in effects:
            resource = self.resources.get(e.resource)
            if resource is None:
                self.error(e.pos, f"effect on undeclared resource '{e.resource}' in {owner}")
            else:
                self.check_state(resource, e.state, e.state_pos, where)
        return len(self.diagnostics) == before
