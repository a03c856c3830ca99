//! Decoding the live conversation of a replay with the decode chain `aptscope decode` uses, so
//! observed replies are paired to the requests sent by the same rules as in the capture; and the
//! session around it that records and displays what crosses (shared by both engines).

use crate::port::{Clock, RxEvent};
use crate::script::{Collector, Msg, Side};
use aptscope_capture::{Chunk, Direction, StreamInfo, Writer};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Format, Renderer};
use aptscope_dissector::record::{Ctx, Decoder, Record};
use aptscope_dissector::table::Dir;
use std::collections::HashMap;

/// The decoded live conversation.
pub struct Observer {
    dec: Decoder,
    coll: Collector,
    /// Renders the live display (text or NDJSON), when there is one.
    show: Option<Renderer>,
    /// Rendered lines for the live display (text or NDJSON), taken by the caller.
    pub lines: Vec<String>,
}

impl Observer {
    /// An observer for `proto`; `display` renders the live timeline (`json`: as NDJSON).
    pub fn new(proto: Proto, display: bool, json: bool) -> Observer {
        let fmt = if json { Format::Json } else { Format::Text };
        Observer {
            dec: Decoder::new(Some(proto)),
            coll: Collector::default(),
            show: display.then(|| Renderer::new(fmt)),
            lines: vec![],
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
        let (coll, show, lines) = (&mut self.coll, &mut self.show, &mut self.lines);
        let mut emit = |r: &Record<'_>| -> Result<(), ()> {
            coll.record(r);
            if let Some(s) = show.as_mut() {
                lines.push(s.line(r).to_string());
            }
            Ok(())
        };
        let _ = self.dec.push(ctx, bytes, &mut emit);
        // A host's write is one command: frame it now, terminator or not (an impersonated
        // device must answer an Elliptec command that has none).
        if side == Side::Host {
            let _ = self.dec.cut(0, Dir::HostToDevice, &mut emit);
        }
        first
    }

    /// End of the conversation: flush partial frames and unanswered requests.
    pub fn finish(&mut self) {
        let (coll, show, lines) = (&mut self.coll, &mut self.show, &mut self.lines);
        let _ = self.dec.finish(&mut |r: &Record<'_>| -> Result<(), ()> {
            coll.record(r);
            if let Some(s) = show.as_mut() {
                lines.push(s.line(r).to_string());
            }
            Ok(())
        });
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

/// The live part shared by the host and device engines: decoding, recording, displaying.
pub(crate) struct Session<'a> {
    pub(crate) obs: Observer,
    rec: Option<&'a mut dyn Writer>,
    out: &'a mut dyn FnMut(&str),
    pub(crate) gone: Option<String>,
    pub(crate) record_error: Option<String>,
    /// Observed replies by the observed request's record number.
    pub(crate) replies: HashMap<u64, Vec<usize>>,
    seen: usize,
    clock: Clock,
}

impl<'a> Session<'a> {
    pub(crate) fn new(
        proto: Proto,
        clock: Clock,
        port: &str,
        mut rec: Option<&'a mut dyn Writer>,
        out: &'a mut dyn FnMut(&str),
        display: bool,
        json: bool,
    ) -> Session<'a> {
        let mut record_error = None;
        if let Some(w) = rec.as_deref_mut() {
            let info = StreamInfo {
                id: 0,
                name: port.to_string(),
                settings: None,
            };
            if let Err(e) = w.stream(&info) {
                record_error = Some(e.to_string());
            }
        }
        Session {
            obs: Observer::new(proto, display, json),
            rec,
            out,
            gone: None,
            record_error,
            replies: HashMap::new(),
            seen: 0,
            clock,
        }
    }

    /// Bytes that crossed at `t_ns`, sent by `side`: record, decode, display. Returns the index
    /// of the first message they completed.
    pub(crate) fn crossed(&mut self, side: Side, t_ns: u64, bytes: &[u8]) -> usize {
        let ts = self.clock.epoch(t_ns);
        if let (Some(w), None) = (self.rec.as_deref_mut(), &self.record_error) {
            let c = Chunk {
                ts_ns: Some(ts),
                dir: match side {
                    Side::Host => Direction::HostToDevice,
                    Side::Device => Direction::DeviceToHost,
                },
                stream: 0,
                bytes,
            };
            if let Err(e) = w.chunk(&c) {
                self.record_error = Some(e.to_string());
            }
        }
        let first = self.obs.feed(side, ts, bytes);
        self.index_new();
        self.show();
        first
    }

    fn index_new(&mut self) {
        let msgs = self.obs.msgs();
        for (i, m) in msgs.iter().enumerate().skip(self.seen) {
            if let (Side::Device, Some(p)) = (m.side, m.pair) {
                self.replies.entry(p).or_default().push(i);
            }
        }
        self.seen = msgs.len();
    }

    fn show(&mut self) {
        for l in self.obs.lines.drain(..) {
            (self.out)(&l);
        }
    }

    pub(crate) fn event(&mut self, ev: RxEvent, remote: Side) {
        match ev {
            RxEvent::Data { t_ns, bytes } => {
                self.crossed(remote, t_ns, &bytes);
            }
            RxEvent::Gone { t_ns, why } => {
                if self.gone.is_none() {
                    self.gone = Some(format!("{why} (at {:.3} s)", t_ns as f64 / 1e9));
                }
            }
        }
    }

    pub(crate) fn finish(&mut self) {
        self.obs.finish();
        self.index_new();
        self.show();
        if let (Some(w), None) = (self.rec.as_deref_mut(), &self.record_error) {
            if let Err(e) = w.finish() {
                self.record_error = Some(e.to_string());
            }
        }
    }
}
