// Spot quadruped as driven in the seed paper's mission (docs/mission.md).
// control_mode is Busy while a movement skill runs; power_switchoff models a
// depleted battery or an emergency stop.

type {
    Float
    GeoPoint
}

skillset spot {

    data battery: Float

    resource {
        power_status {
            state { PowerOff PowerOn }
            initial PowerOff
            transition all
        }
        posture {
            state { Sitting Standing }
            initial Sitting
            transition all
        }
        control_mode {
            state { Idle Busy }
            initial Idle
            transition all
        }
    }

    event {
        power_switchoff {
            guard power_status == PowerOn
            effect {
                power_status -> PowerOff
                posture -> Sitting
            }
        }
    }

    skill init_power {
        precondition {
            sitting: posture == Sitting
            free: control_mode == Idle
            unpowered: power_status == PowerOff
        }
        start { control_mode -> Busy }
        interrupt {
            interrupting true
            effect control_mode -> Idle
        }
        success powered_on {
            effect control_mode -> Idle
            postcondition power_status == PowerOn
        }
        failure no_battery { effect control_mode -> Idle }
    }

    skill safe_poweroff {
        precondition {
            sitting: posture == Sitting
            free: control_mode == Idle
            powered: power_status == PowerOn
        }
        start { control_mode -> Busy }
        interrupt {
            interrupting true
            effect control_mode -> Idle
        }
        success powered_off {
            effect control_mode -> Idle
            postcondition power_status == PowerOff
        }
        failure still_on { effect control_mode -> Idle }
    }

    skill stand_up {
        precondition {
            sitting: posture == Sitting
            free: control_mode == Idle
            powered: power_status == PowerOn
        }
        start { control_mode -> Busy }
        invariant {
            powered {
                guard power_status == PowerOn
                effect control_mode -> Idle
            }
        }
        interrupt {
            interrupting true
            effect control_mode -> Idle
        }
        success standing {
            effect control_mode -> Idle
            postcondition posture == Standing
        }
        failure fell { effect control_mode -> Idle }
    }

    skill sit_down {
        precondition {
            standing: posture == Standing
            free: control_mode == Idle
            powered: power_status == PowerOn
        }
        start { control_mode -> Busy }
        invariant {
            powered {
                guard power_status == PowerOn
                effect control_mode -> Idle
            }
        }
        interrupt {
            interrupting true
            effect control_mode -> Idle
        }
        success sitting {
            effect control_mode -> Idle
            postcondition posture == Sitting
        }
        failure stuck { effect control_mode -> Idle }
    }

    skill go_to_waypoint {
        input target: GeoPoint
        precondition {
            standing: posture == Standing
            free: control_mode == Idle
            powered: power_status == PowerOn
        }
        start { control_mode -> Busy }
        invariant {
            powered {
                guard power_status == PowerOn
                effect control_mode -> Idle
            }
            upright {
                guard posture == Standing
                effect control_mode -> Idle
            }
        }
        progress {
            period 1 sec
            message distance: Float
        }
        interrupt {
            interrupting true
            effect control_mode -> Idle
        }
        success arrived { effect control_mode -> Idle }
        failure not_arrived { effect control_mode -> Idle }
    }

    skill teleop {
        precondition {
            standing: posture == Standing
            free: control_mode == Idle
            powered: power_status == PowerOn
        }
        start { control_mode -> Busy }
        invariant {
            powered {
                guard power_status == PowerOn
                effect control_mode -> Idle
            }
            upright {
                guard posture == Standing
                effect control_mode -> Idle
            }
        }
        interrupt {
            interrupting true
            effect control_mode -> Idle
        }
        success done { effect control_mode -> Idle }
        failure link_lost { effect control_mode -> Idle }
    }
}
