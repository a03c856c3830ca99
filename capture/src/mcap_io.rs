//! MCAP reading and writing (being written).
