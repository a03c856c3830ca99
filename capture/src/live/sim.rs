//! Device simulators (being written).
