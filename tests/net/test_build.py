"""From a skillset to its Petri net, checked by hand on small models (docs/semantics.md §3).

Every expected net below was worked out from the table of docs/semantics.md §3 before being
compared with ``build_net``: places, transition ids and logical names, the exact
pre/post place sets of every variant, the priority pair and the initial marking.
"""

from __future__ import annotations

from skinet.lang.parser import parse_skillset
from skinet.net.build import build_net
from skinet.net.petrinet import PetriNet, Transition

Rendered = tuple[list[str], list[str]]


def render(net: PetriNet, t: Transition) -> Rendered:
    """``(sorted pre place names, sorted post place names)`` of one transition."""
    return sorted(net.places[i] for i in t.pre), sorted(net.places[i] for i in t.post)


def table(net: PetriNet) -> dict[str, Rendered]:
    """Every transition variant by id, in net order (dicts keep insertion order)."""
    return {t.id: render(net, t) for t in net.transitions}


def names(net: PetriNet) -> dict[str, str]:
    """Variant id -> logical name."""
    return {t.id: t.name for t in net.transitions}


def priority_ids(net: PetriNet) -> list[tuple[set[str], set[str]]]:
    return [
        ({net.transitions[i].id for i in high}, {net.transitions[i].id for i in low})
        for high, low in net.priority
    ]


# ---------------------------------------------------------------------------
# A model exercising every row of the docs/semantics.md §3 table

BASIC = """
skillset m {
    resource {
        power { state { Off On } initial Off transition all }
        mode { state { Idle Busy } initial Idle transition all }
    }
    event {
        switch_on { guard power == Off effect power -> On }
        power_cut {
            guard power == On
            effect { power -> Off mode -> Idle }
        }
        reset { effect { power -> Off mode -> Idle } }
    }
    skill k {
        precondition {
            powered: power == On
            free: mode == Idle
        }
        start mode -> Busy
        invariant {
            keep_power { guard power == On effect mode -> Idle }
            plain { guard mode == Busy }
        }
        interrupt {
            interrupting true
            effect mode -> Idle
            postcondition power == Off
        }
        success done {
            effect mode -> Idle
            postcondition power == Off
        }
        failure { effect mode -> Idle }
    }
    skill q {
        success {}
        failure {}
    }
    skill r {
        interrupt { interrupting false }
        success {
            quiet {}
            lit { postcondition power == On }
        }
    }
}
"""

BASIC_PLACES = (
    "power.Off", "power.On", "mode.Idle", "mode.Busy",
    "e_k", "i_k", "e_q", "i_q", "e_r", "i_r",
)  # fmt: skip

BASIC_TABLE: dict[str, Rendered] = {
    # event with a guard and one effect: the guard fixes the source
    "switch_on": (["power.Off"], ["power.On"]),
    # event with a guard and two effects: guard fixes power, mode takes every state
    "power_cut": (["mode.Idle", "power.On"], ["mode.Idle", "power.Off"]),
    "power_cut#2": (["mode.Busy", "power.On"], ["mode.Idle", "power.Off"]),
    # event without a guard: every combination of sources (power, then mode)
    "reset": (["mode.Idle", "power.Off"], ["mode.Idle", "power.Off"]),
    "reset#2": (["mode.Busy", "power.Off"], ["mode.Idle", "power.Off"]),
    "reset#3": (["mode.Idle", "power.On"], ["mode.Idle", "power.Off"]),
    "reset#4": (["mode.Busy", "power.On"], ["mode.Idle", "power.Off"]),
    # start: conjunction of the preconditions, tested by self-loops, plus the effect
    "k.start": (["e_k", "mode.Idle", "power.On"], ["i_k", "mode.Busy", "power.On"]),
    # invariant with an effect: guard negated (power == Off), mode from every state
    "k.inv.keep_power": (["i_k", "mode.Idle", "power.Off"], ["e_k", "mode.Idle", "power.Off"]),
    "k.inv.keep_power#2": (["i_k", "mode.Busy", "power.Off"], ["e_k", "mode.Idle", "power.Off"]),
    # invariant without an effect: a test of the negated guard only
    "k.inv.plain": (["i_k", "mode.Idle"], ["e_k", "mode.Idle"]),
    # interrupt with an effect and a postcondition: mode -> Idle, power forced Off
    "k.interrupt": (["i_k", "mode.Idle", "power.Off"], ["e_k", "mode.Idle", "power.Off"]),
    "k.interrupt#2": (["i_k", "mode.Busy", "power.Off"], ["e_k", "mode.Idle", "power.Off"]),
    "k.interrupt#3": (["i_k", "mode.Idle", "power.On"], ["e_k", "mode.Idle", "power.Off"]),
    "k.interrupt#4": (["i_k", "mode.Busy", "power.On"], ["e_k", "mode.Idle", "power.Off"]),
    # named success mode with effect and postcondition
    "k.success.done": (["i_k", "mode.Idle", "power.Off"], ["e_k", "mode.Idle", "power.Off"]),
    "k.success.done#2": (["i_k", "mode.Busy", "power.Off"], ["e_k", "mode.Idle", "power.Off"]),
    "k.success.done#3": (["i_k", "mode.Idle", "power.On"], ["e_k", "mode.Idle", "power.Off"]),
    "k.success.done#4": (["i_k", "mode.Busy", "power.On"], ["e_k", "mode.Idle", "power.Off"]),
    # unnamed failure mode: logical name without a mode suffix
    "k.failure": (["i_k", "mode.Idle"], ["e_k", "mode.Idle"]),
    "k.failure#2": (["i_k", "mode.Busy"], ["e_k", "mode.Idle"]),
    # no preconditions, empty mode blocks, undeclared interrupt: start and interrupt only
    "q.start": (["e_q"], ["i_q"]),
    "q.interrupt": (["i_q"], ["e_q"]),
    # declared interrupt without effects; an empty named mode; a mode with a postcondition only
    "r.start": (["e_r"], ["i_r"]),
    "r.interrupt": (["i_r"], ["e_r"]),
    "r.success.quiet": (["i_r"], ["e_r"]),
    "r.success.lit": (["i_r", "power.Off"], ["e_r", "power.On"]),
    "r.success.lit#2": (["i_r", "power.On"], ["e_r", "power.On"]),
}


def test_basic_places_and_initial_marking() -> None:
    net = build_net(parse_skillset(BASIC))
    assert net.name == "m"
    assert net.places == BASIC_PLACES
    assert net.marked(net.initial) == ["power.Off", "mode.Idle", "e_k", "e_q", "e_r"]
    assert net.initial == net.marking_of({"power.Off", "mode.Idle", "e_k", "e_q", "e_r"})


def test_basic_transitions_exact() -> None:
    net = build_net(parse_skillset(BASIC))
    assert table(net) == BASIC_TABLE
    assert net.transition_ids() == list(BASIC_TABLE)


def test_basic_logical_names_kinds_and_elements() -> None:
    net = build_net(parse_skillset(BASIC))
    info = {t.id: (t.name, t.kind, t.skill, t.element, t.controllable, t.skillset) for t in net.transitions}
    assert info["reset#3"] == ("reset", "event", None, "reset", False, "m")
    assert info["switch_on"] == ("switch_on", "event", None, "switch_on", False, "m")
    assert info["k.start"] == ("k.start", "start", "k", None, True, "m")
    assert info["k.inv.keep_power#2"] == ("k.inv.keep_power", "invariant", "k", "keep_power", False, "m")
    assert info["k.inv.plain"] == ("k.inv.plain", "invariant", "k", "plain", False, "m")
    assert info["k.interrupt#4"] == ("k.interrupt", "interrupt", "k", None, True, "m")
    assert info["k.success.done#3"] == ("k.success.done", "success", "k", "done", False, "m")
    assert info["k.failure#2"] == ("k.failure", "failure", "k", "", False, "m")
    assert info["q.interrupt"] == ("q.interrupt", "interrupt", "q", None, True, "m")
    assert info["r.success.lit#2"] == ("r.success.lit", "success", "r", "lit", False, "m")
    # every variant id is the logical name, possibly followed by #n (n >= 2, consecutive)
    by_name: dict[str, list[str]] = {}
    for t in net.transitions:
        by_name.setdefault(t.name, []).append(t.id)
    for name, ids in by_name.items():
        assert ids == [name] + [f"{name}#{n}" for n in range(2, len(ids) + 1)]
    assert list(by_name) == [
        "switch_on", "power_cut", "reset",
        "k.start", "k.inv.keep_power", "k.inv.plain", "k.interrupt", "k.success.done", "k.failure",
        "q.start", "q.interrupt",
        "r.start", "r.interrupt", "r.success.quiet", "r.success.lit",
    ]  # fmt: skip


def test_basic_priority_invariants_over_the_rest() -> None:
    net = build_net(parse_skillset(BASIC))
    invariants = {"k.inv.keep_power", "k.inv.keep_power#2", "k.inv.plain"}
    assert priority_ids(net) == [(invariants, set(BASIC_TABLE) - invariants)]
    assert {t.id for t in net.transitions if t.is_invariant} == invariants


def test_eventless_net_drops_events_only() -> None:
    full = build_net(parse_skillset(BASIC))
    net = build_net(parse_skillset(BASIC), eventless=True)
    assert net.name == "m_eventless"
    assert net.places == full.places
    assert net.initial == full.initial
    events = {"switch_on", "power_cut", "power_cut#2", "reset", "reset#2", "reset#3", "reset#4"}
    assert table(net) == {k: v for k, v in BASIC_TABLE.items() if k not in events}
    invariants = {"k.inv.keep_power", "k.inv.keep_power#2", "k.inv.plain"}
    assert priority_ids(net) == [(invariants, set(BASIC_TABLE) - invariants - events)]


def test_no_invariant_no_priority_pair() -> None:
    net = build_net(parse_skillset("skillset s { skill k {} }"))
    assert net.places == ("e_k", "i_k")
    assert table(net) == {"k.start": (["e_k"], ["i_k"]), "k.interrupt": (["i_k"], ["e_k"])}
    assert net.priority == ()
    assert net.marked(net.initial) == ["e_k"]


def test_event_without_guard_or_effect_is_an_empty_transition() -> None:
    # Guard `true`, no effect: one variant that consumes and produces nothing.
    net = build_net(parse_skillset("skillset s { event tick {} }"))
    assert net.places == ()
    assert table(net) == {"tick": ([], [])}
    assert net.initial == 0


def test_start_effect_on_a_resource_not_in_the_precondition() -> None:
    net = build_net(
        parse_skillset(
            """
            skillset s {
                resource {
                    a { state { x y } initial x transition all }
                    b { state { u v w } initial w transition all }
                }
                skill k {
                    precondition p: a == x
                    start { b -> v }
                }
            }
            """
        )
    )
    assert net.places == ("a.x", "a.y", "b.u", "b.v", "b.w", "e_k", "i_k")
    assert net.marked(net.initial) == ["a.x", "b.w", "e_k"]
    assert table(net) == {
        "k.start": (["a.x", "b.u", "e_k"], ["a.x", "b.v", "i_k"]),
        "k.start#2": (["a.x", "b.v", "e_k"], ["a.x", "b.v", "i_k"]),
        "k.start#3": (["a.x", "b.w", "e_k"], ["a.x", "b.v", "i_k"]),
        "k.interrupt": (["i_k"], ["e_k"]),
    }


def test_later_effect_on_same_resource_wins() -> None:
    net = build_net(
        parse_skillset(
            """
            skillset s {
                resource { a { state { x y z } initial x transition all } }
                event e { guard a == x effect { a -> y a -> z } }
            }
            """
        )
    )
    assert table(net) == {"e": (["a.x"], ["a.z"])}


def test_postcondition_overrides_effect_on_same_resource() -> None:
    net = build_net(
        parse_skillset(
            """
            skillset s {
                resource { a { state { x y z } initial x transition all } }
                skill k { success ok { effect a -> y postcondition a == z } }
            }
            """
        )
    )
    assert table(net)["k.success.ok"] == (["a.x", "i_k"], ["a.z", "e_k"])
    assert [render(net, t) for t in net.transitions if t.name == "k.success.ok"] == [
        (["a.x", "i_k"], ["a.z", "e_k"]),
        (["a.y", "i_k"], ["a.z", "e_k"]),
        (["a.z", "i_k"], ["a.z", "e_k"]),
    ]


def test_postcondition_with_several_clauses_gives_one_variant_per_clause() -> None:
    net = build_net(
        parse_skillset(
            """
            skillset s {
                resource {
                    a { state { x y } initial x transition all }
                    b { state { x y } initial x transition all }
                }
                skill k { failure f { postcondition a == y or b == y } }
            }
            """
        )
    )
    assert [(t.id, render(net, t)) for t in net.transitions if t.name == "k.failure.f"] == [
        ("k.failure.f", (["a.x", "i_k"], ["a.y", "e_k"])),
        ("k.failure.f#2", (["a.y", "i_k"], ["a.y", "e_k"])),
        ("k.failure.f#3", (["b.x", "i_k"], ["b.y", "e_k"])),
        ("k.failure.f#4", (["b.y", "i_k"], ["b.y", "e_k"])),
    ]


def test_unsatisfiable_postcondition_still_stops_the_skill() -> None:
    net = build_net(
        parse_skillset(
            """
            skillset s {
                resource { a { state { x y } initial x transition all } }
                skill k { success ok { postcondition a == x and a == y } }
            }
            """
        )
    )
    assert table(net)["k.success.ok"] == (["i_k"], ["e_k"])
    assert [t.id for t in net.transitions if t.name == "k.success.ok"] == ["k.success.ok"]


def test_identical_variants_from_different_clauses_are_kept_once() -> None:
    # Clauses {a: x} and {a: x, b: y}; with the effect b -> y the second clause
    # only reproduces a variant of the first.
    net = build_net(
        parse_skillset(
            """
            skillset s {
                resource {
                    a { state { x y } initial x transition all }
                    b { state { x y } initial x transition all }
                }
                skill k {
                    precondition p: a == x or (a == x and b == y)
                    start b -> y
                }
            }
            """
        )
    )
    assert [(t.id, render(net, t)) for t in net.transitions if t.name == "k.start"] == [
        ("k.start", (["a.x", "b.x", "e_k"], ["a.x", "b.y", "i_k"])),
        ("k.start#2", (["a.x", "b.y", "e_k"], ["a.x", "b.y", "i_k"])),
    ]


# ---------------------------------------------------------------------------
# Legality of moves (docs/semantics.md §3, *Effects*, last column of the table)

LEGAL = """
skillset g {
    resource {
        r { state { A B } initial A transition { A -> B } }
        s { state { X Y } initial X transition all }
    }
    event {
        back { effect r -> A }
        fwd { effect r -> B }
        both { effect { r -> A s -> Y } }
    }
    skill k {
        start r -> A
        invariant inv { guard s == X effect r -> A }
        interrupt { effect { r -> A s -> Y } }
        success ok { effect r -> A }
        failure reset {
            effect { r -> A s -> Y }
            postcondition r == A
        }
    }
}
"""

LEGAL_TABLE: dict[str, Rendered] = {
    # B -> A is not declared: no variant from B (EFFECT_FAILURE); A -> A is the identity
    "back": (["r.A"], ["r.A"]),
    # A -> B declared; B -> B is an identity move, legal
    "fwd": (["r.A"], ["r.B"]),
    "fwd#2": (["r.B"], ["r.B"]),
    # one illegal move voids the set: no variant from r == B at all
    "both": (["r.A", "s.X"], ["r.A", "s.Y"]),
    "both#2": (["r.A", "s.Y"], ["r.A", "s.Y"]),
    # start: no variant from B (START_FAILURE)
    "k.start": (["e_k", "r.A"], ["i_k", "r.A"]),
    # invariant: from B the skill stops and r stays (tested by a self-loop)
    "k.inv.inv": (["i_k", "r.A", "s.Y"], ["e_k", "r.A", "s.Y"]),
    "k.inv.inv#2": (["i_k", "r.B", "s.Y"], ["e_k", "r.B", "s.Y"]),
    # interrupt: from B the whole set is voided, s is not moved either
    "k.interrupt": (["i_k", "r.A", "s.X"], ["e_k", "r.A", "s.Y"]),
    "k.interrupt#2": (["i_k", "r.A", "s.Y"], ["e_k", "r.A", "s.Y"]),
    "k.interrupt#3": (["i_k", "r.B", "s.X"], ["e_k", "r.B", "s.X"]),
    "k.interrupt#4": (["i_k", "r.B", "s.Y"], ["e_k", "r.B", "s.Y"]),
    # mode: from B the skill stops without effects
    "k.success.ok": (["i_k", "r.A"], ["e_k", "r.A"]),
    "k.success.ok#2": (["i_k", "r.B"], ["e_k", "r.B"]),
    # mode with a postcondition: from B the effects are voided (s stays) but the
    # postcondition still moves r from B to A, with no legality check
    "k.failure.reset": (["i_k", "r.A", "s.X"], ["e_k", "r.A", "s.Y"]),
    "k.failure.reset#2": (["i_k", "r.A", "s.Y"], ["e_k", "r.A", "s.Y"]),
    "k.failure.reset#3": (["i_k", "r.B", "s.X"], ["e_k", "r.A", "s.X"]),
    "k.failure.reset#4": (["i_k", "r.B", "s.Y"], ["e_k", "r.A", "s.Y"]),
}


def test_legality_exact_net() -> None:
    net = build_net(parse_skillset(LEGAL))
    assert net.places == ("r.A", "r.B", "s.X", "s.Y", "e_k", "i_k")
    assert net.marked(net.initial) == ["r.A", "s.X", "e_k"]
    assert table(net) == LEGAL_TABLE
    assert priority_ids(net) == [({"k.inv.inv", "k.inv.inv#2"}, set(LEGAL_TABLE) - {"k.inv.inv", "k.inv.inv#2"})]


def test_event_and_start_need_a_legal_move_at_run_time() -> None:
    net = build_net(parse_skillset(LEGAL))
    at_b = net.marking_of({"r.B", "s.X", "e_k"})
    on = {t.name for t in net.transitions if at_b & t.pre_mask == t.pre_mask}
    assert on == {"fwd"}  # no back, no both, no k.start from B


def test_resource_without_transition_clause_allows_identity_only() -> None:
    # No `transition` clause: no move is declared, so only identity moves are legal.
    net = build_net(
        parse_skillset(
            """
            skillset s {
                resource { t { state { P Q } initial P } }
                event frozen { effect t -> Q }
                skill k { success ok { effect t -> Q } }
            }
            """
        )
    )
    assert table(net) == {
        "frozen": (["t.Q"], ["t.Q"]),
        "k.start": (["e_k"], ["i_k"]),
        "k.interrupt": (["i_k"], ["e_k"]),
        "k.success.ok": (["i_k", "t.P"], ["e_k", "t.P"]),
        "k.success.ok#2": (["i_k", "t.Q"], ["e_k", "t.Q"]),
    }


def test_paper_spot_net_shape(paper_system) -> None:
    # A sanity check on a real model: places and the logical transitions of spot.
    net = paper_system.component("spot").net
    assert net.places == (
        "power_status.PowerOff", "power_status.PowerOn", "posture.Sitting", "posture.Standing",
        "control_mode.Idle", "control_mode.Busy",
        "e_init_power", "i_init_power", "e_safe_poweroff", "i_safe_poweroff",
        "e_stand_up", "i_stand_up", "e_sit_down", "i_sit_down",
        "e_go_to_waypoint", "i_go_to_waypoint", "e_teleop", "i_teleop",
    )  # fmt: skip
    assert table(net)["go_to_waypoint.start"] == (
        ["control_mode.Idle", "e_go_to_waypoint", "posture.Standing", "power_status.PowerOn"],
        ["control_mode.Busy", "i_go_to_waypoint", "posture.Standing", "power_status.PowerOn"],
    )
    assert [t.id for t in net.transitions if t.name == "go_to_waypoint.start"] == ["go_to_waypoint.start"]
    assert [render(net, t) for t in net.transitions if t.name == "power_switchoff"] == [
        (
            ["posture.Sitting", "power_status.PowerOn"],
            ["posture.Sitting", "power_status.PowerOff"],
        ),
        (
            ["posture.Standing", "power_status.PowerOn"],
            ["posture.Sitting", "power_status.PowerOff"],
        ),
    ]
    assert [render(net, t) for t in net.transitions if t.name == "teleop.inv.upright"] == [
        (["control_mode.Idle", "i_teleop", "posture.Sitting"], ["control_mode.Idle", "e_teleop", "posture.Sitting"]),
        (["control_mode.Busy", "i_teleop", "posture.Sitting"], ["control_mode.Idle", "e_teleop", "posture.Sitting"]),
    ]
