// A Nav2 mobile base with a docking station (an example written for SkiNet Live).
// It has no skillset manager: nav2.binding.toml binds each skill to one of Nav2's
// action servers, navigator to the lifecycle of bt_navigator, battery and
// charging to /battery_state and the emergency stop to /emergency_stop.
//
// Nav2 accepts a navigate_to_pose goal while the robot sits on its dock: the
// model says so (navigate needs no Undocked), and nav2.props says it is unsafe.

type {
    DockId
}

skillset nav2 {

    resource {
        navigator {
            state { Unconfigured Inactive Active Finalized }
            initial Unconfigured
            transition {
                Unconfigured -> Inactive
                Inactive -> Active
                Active -> Inactive
                Inactive -> Unconfigured
                Unconfigured -> Finalized
                Inactive -> Finalized
                Active -> Finalized
            }
        }
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
        battery {
            state { Ok Low }
            initial Ok
            transition all
        }
        charging {
            state { Charging NotCharging }
            initial Charging
            transition all
        }
    }

    event {
        navigator_configured { guard navigator == Unconfigured effect navigator -> Inactive }
        navigator_activated { guard navigator == Inactive effect navigator -> Active }
        navigator_deactivated { guard navigator == Active effect navigator -> Inactive }
        navigator_cleaned_up { guard navigator == Inactive effect navigator -> Unconfigured }
        navigator_shut_down { guard navigator != Finalized effect navigator -> Finalized }
        battery_low { guard battery == Ok effect battery -> Low }
        battery_recharged { guard battery == Low effect battery -> Ok }
        charging_started { guard charging == NotCharging effect charging -> Charging }
        charging_stopped { guard charging == Charging effect charging -> NotCharging }
        emergency_stop { guard motion == Moving effect motion -> Still }
    }

    skill navigate {
        precondition {
            active: navigator == Active
            still: motion == Still
        }
        start motion -> Moving
        invariant {
            in_motion { guard motion == Moving }
        }
        interrupt {
            interrupting true
            effect motion -> Still
        }
        success arrived { effect motion -> Still }
        failure {
            failed { effect motion -> Still }
            timed_out { effect motion -> Still }
        }
    }

    skill dock_robot {
        input dock: DockId
        precondition {
            undocked: dock == Undocked
            still: motion == Still
        }
        start motion -> Moving
        invariant {
            in_motion { guard motion == Moving }
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
        failure {
            failed { effect motion -> Still }
            not_charging {
                effect {
                    motion -> Still
                    dock -> Docked
                }
            }
        }
    }

    skill undock_robot {
        precondition {
            docked: dock == Docked
            still: motion == Still
        }
        start motion -> Moving
        invariant {
            in_motion { guard motion == Moving }
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
        failure failed { effect motion -> Still }
    }
}
