// A crane whose hoist has two invariants that a start of lower breaks at once: the cascade
// may run them in either order, so lower.start (and hoist.start while lowering) has two
// results.  A test model of the planner (tests/plan): commands with several results.
skillset crane {
    resource {
        hook { state { Up Down } initial Up transition all }
        brake { state { On Off } initial On transition all }
        load { state { Held Dropped Parked } initial Held transition all }
    }
    skill hoist {
        precondition { held: load == Held }
        invariant {
            hook_up { guard hook == Up effect load -> Dropped }
            braked { guard brake == On effect load -> Parked }
        }
        success done { effect load -> Parked }
        failure slipped { effect load -> Dropped }
    }
    skill lower {
        precondition { up: hook == Up }
        start { hook -> Down brake -> Off }
        success lowered { effect { hook -> Up brake -> On } }
        failure jammed { }
    }
    skill reset {
        precondition { dropped: load == Dropped }
        success again { effect load -> Held }
    }
}
