"""A supervised system: several skillsets, their nets, and safety properties.

Pure: built from texts already read (see :mod:`skinet.system.load` for loading).
A *combined marking* maps each skillset name to its net marking (bit mask).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property

from skinet.errors import SourceError
from skinet.lang.model import Resource, Skillset
from skinet.net.build import build_net, idle_place, resource_place, running_place
from skinet.net.petrinet import PetriNet
from skinet.net.semantics import invariants_enabled
from skinet.system.prediction import PredictionOptions
from skinet.props.formula import Property
from skinet.props.parser import parse_properties
from skinet.verify.component import explore_component

Marking = dict[str, int]


@dataclass(frozen=True)
class Component:
    """One skillset of the system with its full and eventless nets."""

    skillset: Skillset
    net: PetriNet
    eventless: PetriNet
    manager: str = ""  # ROS 2 node of the skillset manager, e.g. /spot/spot_skillset_manager
    binding: str = ""  # binding file (docs/semantics.md §9), when plain ROS 2 interfaces stand for a manager
    commanded: frozenset[str] = frozenset()  # events its binding says are commanded (controllable, docs/semantics.md §9)
    commandable: frozenset[str] = frozenset()  # events that change a lifecycle node's resource (could be commanded)

    @property
    def name(self) -> str:
        return self.skillset.name

    @cached_property
    def uncommanded(self) -> PetriNet:
        """The full net without its commanded events: what may happen with no command (docs/semantics.md §8, §9)."""
        return build_net(self.skillset, without=self.commanded) if self.commanded else self.net

    @cached_property
    def commanding(self) -> PetriNet:
        """The eventless net plus the commanded events: what a plan may send and wait for when events are not
        counted as uncontrollable (docs/planning.md: commanded events are commands of the game)."""
        if not self.commanded:
            return self.eventless
        others = frozenset(e.name for e in self.skillset.events) - self.commanded
        return build_net(self.skillset, commanded=self.commanded, without=others)


@dataclass(frozen=True)
class System:
    name: str
    components: tuple[Component, ...]
    properties: tuple[Property, ...]
    sources: Mapping[str, str] = field(default_factory=dict)  # file name -> text, for digests
    prediction: PredictionOptions = PredictionOptions()  # the system file's [prediction] table

    def component(self, name: str) -> Component:
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def nets(self) -> dict[str, PetriNet]:
        return {c.name: c.net for c in self.components}

    def initial_marking(self) -> Marking:
        return {c.name: c.net.initial for c in self.components}

    def property(self, name: str) -> Property:
        for p in self.properties:
            if p.name == name:
                return p
        raise KeyError(name)


def build_system(
    name: str,
    skillsets: Sequence[tuple[Skillset, str] | tuple[Skillset, str, str]],
    properties_text: str,
    properties_source: str = "<properties>",
    sources: Mapping[str, str] | None = None,
    prediction: PredictionOptions | None = None,
    commanded: Mapping[str, frozenset[str]] | None = None,
    commandable: Mapping[str, frozenset[str]] | None = None,
) -> System:
    """Assemble a system from parsed skillsets (each with its manager node, and its binding file
    if it has one) and properties text; ``commanded``: per skillset, the events its binding says
    are commanded (controllable, docs/semantics.md §9); ``commandable``: per skillset, the events that change a resource bound
    to a lifecycle node (a plan's ``none`` names those it would need commanded, docs/planning.md)."""
    seen: set[str] = set()
    components = []
    for ss, manager, *binding in skillsets:
        if ss.name in seen:
            raise SourceError.at(ss.source, ss.pos, f"skillset '{ss.name}' appears twice in system '{name}'")
        seen.add(ss.name)
        events = (commanded or {}).get(ss.name, frozenset())
        components.append(Component(ss, build_net(ss, commanded=events), build_net(ss, eventless=True), manager,
                                    *binding, commanded=events,
                                    commandable=(commandable or {}).get(ss.name, frozenset())))
    props = parse_properties(properties_text, {s[0].name: s[0] for s in skillsets}, properties_source)
    return System(name, tuple(components), tuple(props), dict(sources or {}), prediction or PredictionOptions())


def marking_problems(system: System, marking: Mapping[str, int]) -> list[str]:
    """Why ``marking`` cannot be a state of the live system; empty when it can.

    Two reasons (docs/semantics.md §3): a component marking is *transient* (an invariant is
    violated, and the manager never publishes such a state), or no sequence of
    transitions, events included, reaches it from the initial marking.
    Components share no place, so a combined marking is reachable exactly when
    each component's marking is reachable in its own full net.  Cost: one
    breadth-first search of each component's stable markings (memoised per net).
    """
    problems: list[str] = []
    for c in system.components:
        m = marking[c.name]
        violated = invariants_enabled(c.net, m)
        if violated:
            names = ", ".join(sorted({t.name for t in violated}))
            problems.append(f"'{c.name}' is not stable: invariant violated ({names}); the manager never publishes such a state")
        elif m not in explore_component(c.name, c.net, [c.net.initial]).index:
            problems.append(f"'{c.name}' is not reachable: no sequence of transitions (events included) leads there from its initial marking")
    return problems


def resource_state(component: Component, marking: int, resource: Resource) -> str:
    """The state ``resource`` of ``component`` is in at its net marking ``marking``."""
    idx = component.net.place_index
    return next(s for s in resource.states if marking >> idx(resource_place(resource.name, s)) & 1)


def is_running(component: Component, marking: int, skill: str) -> bool:
    return bool(marking >> component.net.place_index(running_place(skill)) & 1)


def marking_to_json(system: System, marking: Mapping[str, int]) -> dict[str, dict]:
    """``{skillset: {"resources": {r: state}, "running": [skill, ...]}}``."""
    out: dict[str, dict] = {}
    for c in system.components:
        m = marking[c.name]
        resources = {r.name: resource_state(c, m, r) for r in c.skillset.resources}
        running = [k.name for k in c.skillset.skills if is_running(c, m, k.name)]
        out[c.name] = {"resources": resources, "running": running}
    return out


def marking_from_json(system: System, data: object, source: str = "<state>") -> Marking:
    """Inverse of :func:`marking_to_json`; omitted resources are initial, omitted skills idle."""
    if not isinstance(data, dict):
        raise SourceError.at(source, None, "state must be an object mapping skillset names to states")
    unknown = sorted(set(data) - {c.name for c in system.components})
    if unknown:
        names = ", ".join(c.name for c in system.components)
        raise SourceError.at(source, None, f"unknown skillset '{unknown[0]}' (skillsets: {names})")
    marking: Marking = {}
    for c in system.components:
        entry = data.get(c.name, {})
        if not isinstance(entry, dict):
            raise SourceError.at(source, None, f"state of '{c.name}' must be an object")
        extra = sorted(set(entry) - {"resources", "running"})
        if extra:
            raise SourceError.at(source, None, f"unknown key '{extra[0]}' in state of '{c.name}' (keys: resources, running)")
        resources = entry.get("resources", {})
        running = entry.get("running", [])
        if not isinstance(resources, dict) or not isinstance(running, list):
            raise SourceError.at(source, None, f"state of '{c.name}': 'resources' must be an object and 'running' a list")
        places: set[str] = set()
        declared = {r.name: r for r in c.skillset.resources}
        for rname, state in resources.items():
            if not isinstance(state, str):
                raise SourceError.at(source, None, f"state of resource '{c.name}:{rname}' must be a string, not {_json_kind(state)}")
            if rname not in declared:
                raise SourceError.at(source, None, f"unknown resource '{rname}' of '{c.name}' (resources: {', '.join(declared)})")
        for r in c.skillset.resources:
            state = resources.get(r.name, r.initial)
            if state not in r.states:
                raise SourceError.at(source, None, f"unknown state '{state}' of resource '{c.name}:{r.name}' (states: {', '.join(r.states)})")
            places.add(resource_place(r.name, state))
        skills = {k.name for k in c.skillset.skills}
        for k in running:
            if not isinstance(k, str):
                raise SourceError.at(source, None, f"'running' of '{c.name}' must list skill names, not {_json_kind(k)}")
            if k not in skills:
                raise SourceError.at(source, None, f"unknown skill '{k}' of '{c.name}' (skills: {', '.join(sorted(skills))})")
        for k in c.skillset.skills:
            places.add(running_place(k.name) if k.name in running else idle_place(k.name))
        marking[c.name] = c.net.marking_of(places)
    return marking


def _json_kind(value: object) -> str:
    """How JSON calls the type of ``value`` (for error messages)."""
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, bool):
        return "a boolean"
    if value is None:
        return "null"
    return "a number" if isinstance(value, (int, float)) else "a string"
