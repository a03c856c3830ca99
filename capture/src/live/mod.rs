//! Live traffic: device simulators, and taps between a host program and a device (being
//! written).

pub mod serial;
pub mod session;
pub mod sim;
pub mod tap;
