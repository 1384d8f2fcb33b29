// Wheeled base of a mobile manipulator (an example system written for SkiNet
// Live, not from the seed paper).  motion is Moving while a driving skill
// runs; dock says whether the base sits on its charging station.  A bumper hit
// stops the wheels, and the in_motion invariant then stops the driving skill.

skillset base {

    resource {
        motion {
            state { Still Moving }
            initial Still
            transition all
        }
        dock {
            state { Docked Undocked }
            initial Docked
            transition all
        }
    }

    event {
        bumper_hit {
            guard motion == Moving
            effect motion -> Still
        }
    }

    skill undock {
        precondition {
            docked: dock == Docked
            still: motion == Still
        }
        start motion -> Moving
        invariant {
            in_motion {
                guard motion == Moving
            }
        }
        interrupt {
            interrupting true
            effect motion -> Still
        }
        success undocked {
            effect {
                motion -> Still
                dock -> Undocked
            }
        }
        failure stuck {
            effect motion -> Still
        }
    }

    skill navigate {
        precondition {
            undocked: dock == Undocked
            still: motion == Still
        }
        start motion -> Moving
        invariant {
            in_motion {
                guard motion == Moving
            }
        }
        interrupt {
            interrupting true
            effect motion -> Still
        }
        success arrived {
            effect motion -> Still
        }
        failure blocked {
            effect motion -> Still
        }
    }

    skill dock_station {
        precondition {
            undocked: dock == Undocked
            still: motion == Still
        }
        start motion -> Moving
        invariant {
            in_motion {
                guard motion == Moving
            }
        }
        interrupt {
            interrupting true
            effect motion -> Still
        }
        success docked {
            effect {
                motion -> Still
                dock -> Docked
            }
        }
        failure missed {
            effect motion -> Still
        }
    }
}
