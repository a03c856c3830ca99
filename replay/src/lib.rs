//! aptscope-replay: send a capture to a port with its timing, as the host (towards a real
//! controller or a simulator) or as the device (impersonating the captured controller towards a
//! host program), and compare what comes back with what the capture holds.
//!
//! - [`script`]: a capture decoded into messages with sender, time and pairing; selections and
//!   the schedule.
//! - [`sched`]: absolute-deadline waits (no drift) and send-time error statistics.
//! - [`host`] / [`device`]: the two engines; [`diff`]: the field-level comparison of the
//!   messages' typed meanings ([`decoded`]).
//! - [`port`]: serial ports and pseudo-terminals with a timestamping reader thread;
//!   [`safety`]: motion commands and stop-on-abort.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod cli;
pub mod decoded;
pub mod device;
pub mod diff;
pub mod host;
pub mod observe;
pub mod port;
pub mod safety;
pub mod sched;
pub mod script;

pub use cli::{parse_duration, replay_main, ReplayArgs, ReplayOptions, Role};
pub use device::{run_device, DeviceOptions, DeviceOutcome, Responder};
pub use diff::Report;
pub use host::{run_host, HostOptions, Outcome};
pub use port::Link;
pub use script::{Bound, Script, Selection, Side, Timing};
