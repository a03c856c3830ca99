//! Taps (being written).
