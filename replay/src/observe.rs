//! Decoding the live conversation of a replay with the same pipeline `aptscope decode` uses, so
//! observed replies are paired to the requests sent by the same rules as in the capture.

use crate::script::{Collector, Msg, Side};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Ctx, Format, Pipeline};
use aptscope_dissector::table::Dir;

/// The decoded live conversation.
pub struct Observer {
    json: Pipeline,
    text: Option<Pipeline>,
    coll: Collector,
    /// Rendered lines for the live display (text or NDJSON), taken by the caller.
    pub lines: Vec<String>,
    show_json: bool,
}

impl Observer {
    /// An observer for `proto`; `display` renders the live timeline (`json`: as NDJSON).
    pub fn new(proto: Proto, display: bool, json: bool) -> Observer {
        Observer {
            json: Pipeline::new(Some(proto), Format::Json),
            text: (display && !json).then(|| Pipeline::new(Some(proto), Format::Text)),
            coll: Collector::default(),
            lines: vec![],
            show_json: display && json,
        }
    }

    /// Feed bytes that crossed at `ts_ns` (ns since the Unix epoch); returns the index of the
    /// first message they completed in [`Observer::msgs`].
    pub fn feed(&mut self, side: Side, ts_ns: u64, bytes: &[u8]) -> usize {
        let first = self.coll.msgs.len();
        let ctx = Ctx {
            stream: 0,
            dir: Some(match side {
                Side::Host => Dir::HostToDevice,
                Side::Device => Dir::DeviceToHost,
            }),
            ts_ns: Some(ts_ns),
        };
        let (coll, lines, show) = (&mut self.coll, &mut self.lines, self.show_json);
        let mut emit_json = |l: &str| -> Result<(), ()> {
            coll.line(l);
            if show {
                lines.push(l.to_string());
            }
            Ok(())
        };
        let _ = self.json.push_chunk(ctx, bytes, &mut emit_json);
        // A host's write is one command: frame it now, terminator or not (an impersonated
        // device must answer an Elliptec command that has none).
        if side == Side::Host {
            let _ = self.json.cut(0, Dir::HostToDevice, &mut emit_json);
        }
        if let Some(t) = &mut self.text {
            let mut emit_text = |l: &str| -> Result<(), ()> {
                lines.push(l.to_string());
                Ok(())
            };
            let _ = t.push_chunk(ctx, bytes, &mut emit_text);
            if side == Side::Host {
                let _ = t.cut(0, Dir::HostToDevice, &mut emit_text);
            }
        }
        first
    }

    /// End of the conversation: flush partial frames and unanswered requests.
    pub fn finish(&mut self) {
        let (coll, lines, show) = (&mut self.coll, &mut self.lines, self.show_json);
        let _ = self.json.finish(&mut |l: &str| -> Result<(), ()> {
            coll.line(l);
            if show {
                lines.push(l.to_string());
            }
            Ok(())
        });
        if let Some(t) = &mut self.text {
            let _ = t.finish(&mut |l: &str| -> Result<(), ()> {
                lines.push(l.to_string());
                Ok(())
            });
        }
    }

    /// Every message observed so far, in order.
    pub fn msgs(&self) -> &[Msg] {
        &self.coll.msgs
    }

    /// What was observed that is not a message (garbage, damaged frames, unanswered requests).
    pub fn notes(&self) -> &[String] {
        &self.coll.notes
    }
}
