//! Safety: which messages make something move (they ask for confirmation before going to a real
//! port), and the stop commands sent on abort to channels still moving.

use crate::script::Msg;
use aptscope_dissector::apt::{encode_named, Named};
use aptscope_dissector::msg;
use aptscope_dissector::table::{Class, MsgDef};
use aptscope_dissector::Table;
use std::path::Path;

/// Whether the APT message `m` starts a move (from the table: it is completed by an
/// end-of-move message, and is not a stop).
pub fn starts_move(m: &MsgDef) -> bool {
    !m.class.has(Class::STOP)
        && Table::global()
            .replies_of(m)
            .iter()
            .any(|r| r.class.has(Class::END_OF_MOVE))
}

/// [`starts_move`] for the message named `name`.
pub fn apt_starts_move(name: &str) -> bool {
    Table::global().msg_by_name(name).is_some_and(starts_move)
}

/// Whether a host message makes hardware move or changes an output (asked for confirmation
/// before a real port): APT messages of `class=motion` (or `stop`) in the table and those that
/// start a move; Elliptec commands whose class in the command table may move the stage
/// (motions, frequency searches and current-curve scans, energising a motor). A message the
/// tables do not know is not replayed (it has no name), so none is guessed at.
pub fn is_motion(m: &Msg) -> bool {
    match (m.def, m.cmd) {
        (Some(d), _) => starts_move(d) || d.class.has(Class::MOTION) || d.class.has(Class::STOP),
        (None, Some(c)) => c.class.moves(),
        (None, None) => false,
    }
}

/// Whether `path` is a pseudo-terminal (a simulator or a tap), where no confirmation is needed.
pub fn is_pseudo_terminal(path: &Path) -> bool {
    let real = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    let s = real.to_string_lossy();
    s.starts_with("/dev/pts/")
        || s.starts_with("/dev/pty")
        || s.starts_with("/dev/tty") && {
            // BSD-style /dev/ttyp0 … pseudo-terminals.
            s.len() == 10 && s.as_bytes().get(8).is_some_and(|c| b"pqrs".contains(c))
        }
}

/// A channel of a device that a replayed command set moving.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Moving {
    /// Destination address of the move.
    pub dst: u8,
    /// Channel (1 when the message names none).
    pub chan: i64,
}

impl Moving {
    /// The channel an APT move command `m` sets moving, if it is one.
    pub fn of(m: &Msg) -> Option<Moving> {
        if !starts_move(m.def?) {
            return None;
        }
        Some(Moving {
            dst: m.addr?,
            chan: m.channel().unwrap_or(1),
        })
    }

    /// MOT_MOVE_STOP (profiled) for this channel, from the host.
    pub fn stop_command(&self) -> Option<Vec<u8>> {
        let chan = self.chan.to_string();
        let table = Table::global();
        encode_named(
            table,
            &Named {
                name: table.msg(msg::MOT_MOVE_STOP)?.name,
                sub: None,
                values: &[("chan_ident", &chan), ("stop_mode", "PROFILED")],
                form: Some("hdr"),
                dst: self.dst,
                src: 0x01,
            },
        )
        .ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moves_come_from_the_table() {
        assert!(apt_starts_move("MOT_MOVE_ABSOLUTE"));
        assert!(apt_starts_move("MOT_MOVE_HOME"));
        assert!(!apt_starts_move("MOT_MOVE_STOP"));
        assert!(!apt_starts_move("HW_REQ_INFO"));
    }

    #[test]
    fn stop_command_is_a_profiled_move_stop() {
        let m = Moving { dst: 0x50, chan: 1 };
        assert_eq!(
            m.stop_command(),
            Some(vec![0x65, 0x04, 0x01, 0x02, 0x50, 0x01])
        );
    }

    #[test]
    fn pseudo_terminals_are_recognised() {
        assert!(is_pseudo_terminal(Path::new("/dev/pts/3")));
        assert!(!is_pseudo_terminal(Path::new("/dev/ttyUSB0")));
    }
}
