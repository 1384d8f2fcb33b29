// Arm of a mobile manipulator (an example system written for SkiNet Live).
// Unlike the seed paper's arm, its skills change the arm's pose only when they
// end: while unfold runs the arm still counts as Folded, and its success (or a
// jam half-way) leaves it Unfolded.  mutex is Busy while an arm skill runs.

skillset arm {

    resource {
        mutex {
            state { Free Busy }
            initial Free
            transition all
        }
        pose {
            state { Folded Unfolded Holding }
            initial Folded
            transition all
        }
    }

    skill unfold {
        precondition {
            folded: pose == Folded
            free: mutex == Free
        }
        start mutex -> Busy
        interrupt {
            interrupting true
            effect mutex -> Free
        }
        success unfolded {
            effect {
                mutex -> Free
                pose -> Unfolded
            }
        }
        failure jammed {
            effect {
                mutex -> Free
                pose -> Unfolded
            }
        }
    }

    skill pick {
        precondition {
            unfolded: pose == Unfolded
            free: mutex == Free
        }
        start mutex -> Busy
        interrupt {
            interrupting true
            effect mutex -> Free
        }
        success picked {
            effect {
                mutex -> Free
                pose -> Holding
            }
        }
        failure missed {
            effect mutex -> Free
        }
    }

    skill place {
        precondition {
            holding: pose == Holding
            free: mutex == Free
        }
        start mutex -> Busy
        interrupt {
            interrupting true
            effect mutex -> Free
        }
        success placed {
            effect {
                mutex -> Free
                pose -> Unfolded
            }
        }
        failure dropped {
            effect {
                mutex -> Free
                pose -> Unfolded
            }
        }
    }

    skill fold {
        precondition {
            unfolded: pose == Unfolded
            free: mutex == Free
        }
        start mutex -> Busy
        interrupt {
            interrupting true
            effect mutex -> Free
        }
        success folded {
            effect {
                mutex -> Free
                pose -> Folded
            }
        }
        failure jammed {
            effect mutex -> Free
        }
    }
}
