// Kinova Jaco arm mounted on Spot, as in the seed paper's mission
// (docs/mission.md).  mutex is Busy while a movement skill runs;
// arm_status is HP (home position), RD (ready position), Moving, or Away
// (somewhere else after a joystick session or an interrupted movement).
// An emergency stop leaves the arm Away; the in_motion invariant then stops
// the running movement skill and frees the mutex.

type {
    Float
}

skillset manipulator {

    resource {
        mutex {
            state { Free Busy }
            initial Free
            transition all
        }
        arm_status {
            state { HP RD Moving Away }
            initial HP
            transition {
                HP -> Moving
                RD -> Moving
                Away -> Moving
                Moving -> HP
                Moving -> RD
                Moving -> Away
            }
        }
    }

    event {
        arm_emergency_stop {
            guard arm_status == Moving
            effect arm_status -> Away
        }
    }

    skill arm_ready {
        precondition {
            at_home: arm_status == HP
            free: mutex == Free
        }
        start {
            mutex -> Busy
            arm_status -> Moving
        }
        invariant {
            in_motion {
                guard arm_status == Moving
                effect mutex -> Free
            }
        }
        interrupt {
            interrupting true
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
        success ready {
            effect {
                mutex -> Free
                arm_status -> RD
            }
        }
        failure blocked {
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
    }

    skill arm_joystick {
        precondition {
            placed: arm_status == RD or arm_status == Away
            free: mutex == Free
        }
        start {
            mutex -> Busy
            arm_status -> Moving
        }
        invariant {
            in_motion {
                guard arm_status == Moving
                effect mutex -> Free
            }
        }
        progress {
            period 100 ms
            message effort: Float
        }
        interrupt {
            interrupting true
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
        success released {
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
        failure lost {
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
    }

    skill arm_moving_to_RD {
        precondition {
            away: arm_status == Away
            free: mutex == Free
        }
        start {
            mutex -> Busy
            arm_status -> Moving
        }
        invariant {
            in_motion {
                guard arm_status == Moving
                effect mutex -> Free
            }
        }
        interrupt {
            interrupting true
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
        success at_ready {
            effect {
                mutex -> Free
                arm_status -> RD
            }
        }
        failure blocked {
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
    }

    skill arm_RD_to_HP {
        precondition {
            at_ready: arm_status == RD
            free: mutex == Free
        }
        start {
            mutex -> Busy
            arm_status -> Moving
        }
        invariant {
            in_motion {
                guard arm_status == Moving
                effect mutex -> Free
            }
        }
        interrupt {
            interrupting true
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
        success at_home {
            effect {
                mutex -> Free
                arm_status -> HP
            }
        }
        failure blocked {
            effect {
                mutex -> Free
                arm_status -> Away
            }
        }
    }
}
