//! The one decode chain: captured chunks in, typed [`Record`]s out.
//!
//! A [`Decoder`] does protocol detection, keeps one framer per (stream, direction) lane, decodes
//! frames, tracks devices' units and pairs requests with replies (APT pairer, Elliptec bus).
//! Every view — text and NDJSON ([`crate::pipeline`]), MCAP, the terminal UI's index, `info`,
//! `stats`, the replay — reads the records it yields; none rebuilds the chain.
//!
//! Records borrow the framers' buffers: they are handed to a callback and live until it returns
//! (zero-copy; a consumer that keeps one copies what it needs). Pure: the caller feeds chunks.
//!
//! Frames come out in the order they complete, which for a capture read in time order is time
//! order: the lanes are merged by time.

use crate::apt::{AptFrame, AptFramer, GarbageKind, Item as AptItem};
use crate::detect::{detect, Detection, Proto, SAMPLE};
use crate::diag::{Diag, DiagKind};
use crate::ell::{Bus, EllFrame, EllFramer, Expired, Item as EllItem, Observation};
use crate::pair::{AptPairer, PairInfo};
use crate::table::Dir;
use crate::units::{Notice, Scale, Tracker, UnitsOpts};
use crate::Table;
use std::collections::VecDeque;

/// A chunk's context: where and when its bytes were captured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ctx {
    /// Stream (port/device) index.
    pub stream: u32,
    /// Direction, when the capture records it.
    pub dir: Option<Dir>,
    /// Capture time in ns, when recorded.
    pub ts_ns: Option<u64>,
}

/// Where and when a frame or garbage run was captured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Meta {
    /// Record number, from 1, counting frames and garbage runs.
    pub n: u64,
    /// Stream (port/device) index.
    pub stream: u32,
    /// Direction as the capture recorded it.
    pub cap_dir: Option<Dir>,
    /// Capture time in ns: when the record's first byte arrived (a framer that waits for the
    /// next byte to know a frame has ended does not move its time), so records of a stream come
    /// in time order.
    pub ts_ns: Option<u64>,
    /// Seconds since the first timed chunk of the capture.
    pub rel_s: Option<f64>,
    /// Offset of its first byte in the whole capture: the bytes of every stream and direction
    /// in the order they were read (the frame's own `offset` counts in its lane only).
    pub cap_offset: u64,
}

/// A decoded APT frame with what the chain learnt about it.
#[derive(Debug)]
pub struct AptRec<'r> {
    /// Its context.
    pub meta: Meta,
    /// The decoded frame.
    pub frame: &'r AptFrame<'r, 'static>,
    /// Pairing.
    pub pair: &'r PairInfo,
    /// The stage conversion that applies to its motion values, if any.
    pub scale: Option<&'r Scale>,
}

impl AptRec<'_> {
    /// Direction: the capture's, else the message's own when the table fixes it.
    pub fn dir(&self) -> Option<Dir> {
        self.meta
            .cap_dir
            .or_else(|| self.frame.msg.map(|m| m.dir).filter(|d| *d != Dir::Both))
    }
}

/// A decoded Elliptec frame with what the bus made of it.
#[derive(Debug)]
pub struct EllRec<'r> {
    /// Its context.
    pub meta: Meta,
    /// The decoded frame (an `unsolicited` diagnostic already added).
    pub frame: &'r EllFrame<'r>,
    /// Pairing and the module's state.
    pub obs: &'r Observation,
}

/// Bytes that are not a frame.
#[derive(Debug)]
pub struct GarbageRec<'r> {
    /// Its context (time of its first byte).
    pub meta: Meta,
    /// Protocol whose framer rejected the bytes.
    pub proto: Proto,
    /// Offset of the first byte in its lane.
    pub offset: u64,
    /// The bytes.
    pub bytes: &'r [u8],
    /// What the APT framer saw (APT only).
    pub kind: Option<GarbageKind>,
}

/// A request that got no reply before its timeout or the end of the capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoReply {
    /// Protocol of the request.
    pub proto: Proto,
    /// Stream of the request.
    pub stream: u32,
    /// Record number of the request.
    pub n: u64,
    /// Its offset in its lane.
    pub offset: u64,
    /// Its name (APT) or mnemonic (Elliptec).
    pub name: &'static str,
}

impl NoReply {
    /// The diagnostic saying so.
    pub fn diag(&self) -> Diag {
        Diag {
            offset: self.offset,
            kind: DiagKind::NoReply { cmd: self.n },
        }
    }
}

/// One record of the stream.
#[derive(Debug)]
pub enum Record<'r> {
    /// The protocol chosen from the first bytes.
    Detect {
        /// Chosen protocol.
        proto: Proto,
        /// The detector's scores (`proto` is `None` when uncertain).
        detection: Detection,
        /// Bytes judged.
        sample: usize,
    },
    /// A stream (port, device) the capture names.
    Stream {
        /// Its index.
        id: u32,
        /// Its name.
        name: &'r str,
        /// Line settings, when known.
        settings: Option<&'r str>,
    },
    /// A problem of the input itself (bad hex text, a corrupt capture record).
    Input(Diag),
    /// A capture-file problem given as text.
    FileDiag {
        /// Offset in the file.
        offset: u64,
        /// Kind (`truncated_record` …).
        kind: &'r str,
        /// Text.
        msg: &'r str,
    },
    /// The unit conversion that applies to a device from now on.
    Units(&'r Notice),
    /// An APT frame.
    Apt(AptRec<'r>),
    /// An Elliptec frame.
    Ell(EllRec<'r>),
    /// Bytes outside frames.
    Garbage(GarbageRec<'r>),
    /// A request without reply.
    NoReply(NoReply),
}

impl Record<'_> {
    /// The record's context, for frames and garbage.
    pub fn meta(&self) -> Option<&Meta> {
        match self {
            Record::Apt(r) => Some(&r.meta),
            Record::Ell(r) => Some(&r.meta),
            Record::Garbage(r) => Some(&r.meta),
            _ => None,
        }
    }
}

/// A diagnostic held back while the protocol is detected.
enum Held {
    Input(Diag),
    File {
        offset: u64,
        kind: String,
        msg: String,
    },
}

/// A lane's two framers: the protocol detected says which one is fed.
struct Framers {
    apt: AptFramer<'static>,
    ell: EllFramer,
}

struct Lane {
    stream: u32,
    dir: Option<Dir>,
    framers: Framers,
    /// Time of the latest chunk: the time a frame completing now gets.
    ts: Option<u64>,
    /// Bytes pushed so far, and the (first offset, time) of each timed chunk not yet behind
    /// the records emitted: garbage gets the time its first byte arrived.
    pushed: u64,
    times: VecDeque<(u64, u64)>,
    /// (lane offset, capture offset) of each chunk not yet behind the records emitted.
    starts: VecDeque<(u64, u64)>,
}

impl Lane {
    /// Time of the byte at stream offset `at` from a lane's `times` (else `latest`). Records
    /// come in offset order: what is before `at` is forgotten.
    fn time_at(times: &mut VecDeque<(u64, u64)>, latest: Option<u64>, at: u64) -> Option<u64> {
        while times.get(1).is_some_and(|(o, _)| *o <= at) {
            times.pop_front();
        }
        times
            .front()
            .filter(|(o, _)| *o <= at)
            .map(|(_, t)| *t)
            .or(latest)
    }

    /// Capture-wide offset of the byte at lane offset `at` (see [`Lane::time_at`]).
    fn cap_at(starts: &mut VecDeque<(u64, u64)>, at: u64) -> u64 {
        while starts.get(1).is_some_and(|(o, _)| *o <= at) {
            starts.pop_front();
        }
        starts
            .front()
            .filter(|(o, _)| *o <= at)
            .map_or(at, |(o, c)| c + (at - o))
    }
}

/// The decoder for one capture: the one chain from chunks to [`Record`]s.
pub struct Decoder {
    proto: Option<Proto>,
    /// Chunks held back until the protocol is known.
    sample: Vec<(Ctx, Vec<u8>)>,
    sample_len: usize,
    /// Input and file diagnostics met while the sample is held, with the number of sample
    /// chunks before them: emitted in their place among the sample's records.
    held: Vec<(usize, Held)>,
    lanes: Vec<Lane>,
    track: Track,
    first_ts: Option<u64>,
    n: u64,
    /// Bytes fed so far, all lanes.
    cap_pushed: u64,
    /// The detector's verdict, once the protocol was detected.
    detection: Option<Detection>,
}

impl Decoder {
    /// A decoder for `proto`, or auto-detection from the first 4 KiB when `None`.
    pub fn new(proto: Option<Proto>) -> Self {
        Decoder {
            proto,
            sample: vec![],
            sample_len: 0,
            held: vec![],
            lanes: vec![],
            track: Track {
                buses: vec![],
                pairers: vec![],
                frames: 0,
                reply_timeout: None,
                units: Tracker::new(UnitsOpts::default()),
                expired: vec![],
                pinfo: PairInfo::default(),
            },
            first_ts: None,
            n: 0,
            cap_pushed: 0,
            detection: None,
        }
    }

    /// Convert APT motion values to physical units with this stage or scale (see
    /// [`crate::units`]). Without it only devices with a built-in stage convert.
    pub fn set_units(&mut self, opts: UnitsOpts) {
        self.track.units = Tracker::new(opts);
    }

    /// Use one reply timeout for every request instead of the per-message defaults.
    pub fn set_reply_timeout(&mut self, ns: u64) {
        self.track.reply_timeout = Some(ns);
    }

    /// The protocol in use (after detection).
    pub fn proto(&self) -> Option<Proto> {
        self.proto
    }

    /// The detector's verdict (`None` before detection, or when the protocol was given).
    pub fn detection(&self) -> Option<&Detection> {
        self.detection.as_ref()
    }

    /// Frames and garbage runs numbered so far.
    pub fn records(&self) -> u64 {
        self.n
    }

    /// Frames emitted so far (a capture in which none frames is not one of these protocols).
    pub fn frames(&self) -> u64 {
        self.track.frames
    }

    /// Captured bytes fed so far, every stream and direction.
    pub fn bytes(&self) -> u64 {
        self.cap_pushed
    }

    /// Time of the first timed chunk.
    pub fn first_ts(&self) -> Option<u64> {
        self.first_ts
    }

    /// Feed one captured chunk; each record is passed to `emit`.
    pub fn push<E>(
        &mut self,
        ctx: Ctx,
        chunk: &[u8],
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto.is_none() {
            // A first chunk of a whole sample or more (a file read at once) is judged on its
            // first bytes and then fed as it is: copied whole into the sample (and into the
            // bytes judged), a 10 MB file was 20 MB copied and 5,000 pages touched before
            // its first record.
            let whole = self.sample.is_empty() && chunk.len() >= SAMPLE;
            let kept = if whole { &chunk[..SAMPLE] } else { chunk };
            self.sample.push((ctx, kept.to_vec()));
            self.sample_len += chunk.len();
            if self.sample_len < SAMPLE {
                return Ok(());
            }
            self.choose(emit)?;
            if !whole {
                return self.replay_sample(emit);
            }
            // The records held come before the chunk, as they would before its replay.
            self.sample.clear();
            self.replay_sample(emit)?;
        }
        self.feed(ctx, chunk, emit)
    }

    /// Say that the sender of `dir` on `stream` has paused (a live source knows: its write is
    /// over): an Elliptec host command complete but for its optional terminator is framed now
    /// instead of when the next byte comes. APT frames need no such hint.
    pub fn cut<E>(
        &mut self,
        stream: u32,
        dir: Dir,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto != Some(Proto::Elliptec) {
            return Ok(());
        }
        for j in 0..self.lanes.len() {
            if self.lanes[j].stream == stream && self.lanes[j].dir == Some(dir) {
                self.lanes[j].framers.ell.cut();
                self.drain(j, emit)?;
            }
        }
        Ok(())
    }

    /// Report a problem of the input itself, with its offset in the file.
    pub fn input_diag<E>(
        &mut self,
        d: &Diag,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto.is_none() {
            self.held.push((self.sample.len(), Held::Input(*d)));
            return Ok(());
        }
        emit(&Record::Input(*d))
    }

    /// Report a capture-file problem given as text (kind and message) at a file offset.
    pub fn file_diag<E>(
        &mut self,
        offset: u64,
        kind: &str,
        msg: &str,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto.is_none() {
            let h = Held::File {
                offset,
                kind: kind.to_string(),
                msg: msg.to_string(),
            };
            self.held.push((self.sample.len(), h));
            return Ok(());
        }
        emit(&Record::FileDiag { offset, kind, msg })
    }

    /// Report a stream (port, device) the capture names: its index, name and line settings.
    pub fn stream_info<E>(
        &mut self,
        id: u32,
        name: &str,
        settings: Option<&str>,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        emit(&Record::Stream { id, name, settings })
    }

    /// End of capture: flush what is left and report requests that got no reply.
    pub fn finish<E>(
        &mut self,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto.is_none() {
            if self.sample.is_empty() {
                // Nothing to detect from: only the diagnostics.
                for (_, h) in std::mem::take(&mut self.held) {
                    emit_held(&h, emit)?;
                }
                return Ok(());
            }
            self.choose(emit)?;
            self.replay_sample(emit)?;
        }
        for i in 0..self.lanes.len() {
            self.lanes[i].framers.apt.finish();
            self.lanes[i].framers.ell.finish();
            self.drain(i, emit)?;
        }
        let mut left = vec![];
        for (stream, bus) in self.track.buses.iter_mut() {
            left.extend(bus.finish().into_iter().map(|e| ell_no_reply(*stream, &e)));
        }
        for (stream, p) in self.track.pairers.iter_mut() {
            left.extend(p.finish().into_iter().map(|u| NoReply {
                proto: Proto::Apt,
                stream: *stream,
                n: u.n,
                offset: u.offset,
                name: u.name,
            }));
        }
        left.sort_by_key(|e| e.n);
        for e in &left {
            emit(&Record::NoReply(*e))?;
        }
        Ok(())
    }

    fn replay_sample<E>(
        &mut self,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        let mut held = std::mem::take(&mut self.held).into_iter().peekable();
        for (i, (ctx, bytes)) in std::mem::take(&mut self.sample).into_iter().enumerate() {
            while let Some((_, h)) = held.next_if(|(at, _)| *at <= i) {
                emit_held(&h, emit)?;
            }
            self.feed(ctx, &bytes, emit)?;
        }
        for (_, h) in held {
            emit_held(&h, emit)?;
        }
        self.sample_len = 0;
        Ok(())
    }

    /// Decide the protocol now, from the bytes held so far, when detection is certain on them
    /// (a live source may stay short of the 4 KiB sample for long: its traffic shows at once);
    /// the held records follow. Returns whether the protocol is known.
    pub fn detect_if_certain<E>(
        &mut self,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<bool, E> {
        if self.proto.is_some() {
            return Ok(true);
        }
        if self.sample.is_empty() || self.judge().0.proto.is_none() {
            return Ok(false);
        }
        self.choose(emit)?;
        self.replay_sample(emit)?;
        Ok(true)
    }

    /// Detection on the busiest lane of the sample (interleaved lanes would confuse both
    /// framers), and the bytes judged.
    fn judge(&self) -> (Detection, usize) {
        let mut bytes = Vec::with_capacity(SAMPLE);
        let lane_of = |c: &Ctx| (c.stream, c.dir.map(|d| d.as_str()));
        let mut best: Option<((u32, Option<&str>), usize)> = None;
        for (c, _) in &self.sample {
            let k = lane_of(c);
            let total: usize = self
                .sample
                .iter()
                .filter(|(x, _)| lane_of(x) == k)
                .map(|(_, y)| y.len())
                .sum();
            if best.is_none_or(|(_, t)| total > t) {
                best = Some((k, total));
            }
        }
        if let Some((k, _)) = best {
            for (c, b) in &self.sample {
                if lane_of(c) == k {
                    // What `detect` looks at, no more.
                    let room = SAMPLE.saturating_sub(bytes.len());
                    bytes.extend_from_slice(b.get(..room).unwrap_or(b));
                }
            }
        }
        (detect(&bytes), bytes.len().min(SAMPLE))
    }

    fn choose<E>(&mut self, emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>) -> Result<(), E> {
        let (d, sample) = self.judge();
        let proto = d.proto.unwrap_or(if d.elliptec > d.apt {
            Proto::Elliptec
        } else {
            Proto::Apt
        });
        self.proto = Some(proto);
        self.detection = Some(d);
        emit(&Record::Detect {
            proto,
            detection: d,
            sample,
        })
    }

    fn lane(&mut self, ctx: &Ctx) -> usize {
        if let Some(i) = self
            .lanes
            .iter()
            .position(|l| l.stream == ctx.stream && l.dir == ctx.dir)
        {
            return i;
        }
        self.lanes.push(Lane {
            stream: ctx.stream,
            dir: ctx.dir,
            framers: Framers {
                apt: AptFramer::new(Table::global()),
                ell: EllFramer::new(),
            },
            ts: None,
            pushed: 0,
            times: Default::default(),
            starts: Default::default(),
        });
        self.lanes.len() - 1
    }

    fn feed<E>(
        &mut self,
        ctx: Ctx,
        chunk: &[u8],
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.first_ts.is_none() {
            self.first_ts = ctx.ts_ns;
        }
        let i = self.lane(&ctx);
        if self.proto == Some(Proto::Elliptec) && ctx.dir.is_some() {
            // The other direction speaks: the host's last command is over, terminator or not.
            for j in 0..self.lanes.len() {
                let l = &self.lanes[j];
                if j != i && l.stream == ctx.stream && l.dir.is_some() && l.dir != ctx.dir {
                    self.lanes[j].framers.ell.cut();
                    self.drain(j, emit)?;
                }
            }
        }
        let lane = &mut self.lanes[i];
        if let Some(t) = ctx.ts_ns {
            lane.ts = Some(t);
            lane.times.push_back((lane.pushed, t));
        }
        if !chunk.is_empty() {
            lane.starts.push_back((lane.pushed, self.cap_pushed));
        }
        lane.pushed += chunk.len() as u64;
        self.cap_pushed += chunk.len() as u64;
        match self.proto {
            Some(Proto::Apt) => lane.framers.apt.push(chunk),
            _ => lane.framers.ell.push(chunk),
        }
        self.drain(i, emit)
    }

    /// Emits the records of what lane `i`'s framer has completed, with the protocol's
    /// [`Framer`].
    fn drain<E>(
        &mut self,
        i: usize,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto == Some(Proto::Apt) {
            self.drain_with::<AptSide, E>(i, emit)
        } else {
            self.drain_with::<EllSide, E>(i, emit)
        }
    }

    /// The one decode loop: each item of the lane's framer numbered, timed and placed, a frame
    /// handed to `P`, a garbage run emitted, then the requests that expired meanwhile.
    fn drain_with<P: Framer, E>(
        &mut self,
        i: usize,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        let first = self.first_ts;
        let (ts, stream, cap_dir) = (self.lanes[i].ts, self.lanes[i].stream, self.lanes[i].dir);
        // A record's context: the time of its first byte.
        let meta = |n: u64, ts: Option<u64>, cap_offset: u64| Meta {
            n,
            stream,
            cap_dir,
            ts_ns: ts,
            rel_s: match (ts, first) {
                (Some(a), Some(b)) => Some(a.saturating_sub(b) as f64 / 1e9),
                _ => None,
            },
            cap_offset,
        };
        let state = P::state(&mut self.track, stream);
        loop {
            let lane = &mut self.lanes[i];
            let Some(item) = P::next_item(&mut lane.framers) else {
                break;
            };
            let (Item::Frame { offset: at, .. } | Item::Garbage { offset: at, .. }) = item;
            let first_ts = Lane::time_at(&mut lane.times, ts, at);
            let cap_offset = Lane::cap_at(&mut lane.starts, at);
            self.n += 1;
            let meta = meta(self.n, first_ts, cap_offset);
            match item {
                Item::Frame {
                    offset,
                    bytes,
                    truncated,
                } => {
                    let frame = RawFrame {
                        offset,
                        bytes,
                        truncated,
                    };
                    if !P::frame(&mut self.track, state, meta, frame, emit)? {
                        continue;
                    }
                }
                Item::Garbage {
                    offset,
                    bytes,
                    kind,
                } => {
                    emit(&Record::Garbage(GarbageRec {
                        meta,
                        proto: P::PROTO,
                        offset,
                        bytes,
                        kind,
                    }))?;
                }
            }
            self.track.emit_expired(emit)?;
        }
        Ok(())
    }
}

/// What the chain keeps besides the lanes: each stream's pairing (APT pairer, Elliptec bus),
/// the devices' units, and the records waiting to be emitted.
struct Track {
    buses: Vec<(u32, Bus)>,
    pairers: Vec<(u32, AptPairer)>,
    /// Frames emitted so far (APT and Elliptec).
    frames: u64,
    reply_timeout: Option<u64>,
    /// Models seen per device and the stage conversion of motion values.
    units: Tracker,
    expired: Vec<NoReply>,
    /// Pairing of the current APT frame (one reused for every frame).
    pinfo: PairInfo,
}

impl Track {
    fn emit_expired<E>(
        &mut self,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        for e in std::mem::take(&mut self.expired) {
            emit(&Record::NoReply(e))?;
        }
        Ok(())
    }
}

/// A frame or a garbage run of either protocol's framer, as the decode loop reads it.
enum Item<'a> {
    Frame {
        offset: u64,
        bytes: &'a [u8],
        truncated: bool,
    },
    Garbage {
        offset: u64,
        bytes: &'a [u8],
        /// What the APT framer saw (APT only).
        kind: Option<GarbageKind>,
    },
}

/// A protocol's framer item (`AptItem`, `EllItem`: the same variants) as an [`Item`], its
/// garbage kind mapped by `kind`.
macro_rules! item {
    ($it:expr, $ty:ident, $kind:expr) => {
        match $it {
            $ty::Frame {
                offset,
                bytes,
                truncated,
            } => Item::Frame {
                offset,
                bytes,
                truncated,
            },
            $ty::Garbage {
                offset,
                bytes,
                kind,
            } => Item::Garbage {
                offset,
                bytes,
                kind: $kind(kind),
            },
        }
    };
}

/// A frame's bytes as its framer found them, before decoding.
struct RawFrame<'a> {
    offset: u64,
    bytes: &'a [u8],
    truncated: bool,
}

/// One protocol's part of the decode loop ([`Decoder::drain_with`]): the framer it reads in a
/// lane, and what it makes of a frame (decode, pairing, units).
trait Framer {
    /// The protocol, named by its garbage records.
    const PROTO: Proto;
    /// The index of `stream`'s pairing state in `track`, made on first use.
    fn state(track: &mut Track, stream: u32) -> usize;
    /// The next frame or garbage run the lane's framer of this protocol has completed.
    fn next_item(framers: &mut Framers) -> Option<Item<'_>>;
    /// Decodes, pairs and emits one frame (with its record's context `meta`); `false` when the
    /// bytes do not decode (nothing emitted).
    fn frame<E>(
        track: &mut Track,
        state: usize,
        meta: Meta,
        raw: RawFrame<'_>,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<bool, E>;
}

/// The index of `stream`'s entry in `list`, made with `make` on first use.
fn slot<T>(list: &mut Vec<(u32, T)>, stream: u32, make: impl FnOnce() -> T) -> usize {
    match list.iter().position(|(s, _)| *s == stream) {
        Some(i) => i,
        None => {
            list.push((stream, make()));
            list.len() - 1
        }
    }
}

/// APT: the pairer and the units tracker see every frame.
struct AptSide;

impl Framer for AptSide {
    const PROTO: Proto = Proto::Apt;

    fn state(track: &mut Track, stream: u32) -> usize {
        let timeout_ns = track.reply_timeout;
        slot(&mut track.pairers, stream, || {
            let mut p = AptPairer::new();
            p.timeout_ns = timeout_ns;
            p
        })
    }

    #[inline]
    fn next_item(framers: &mut Framers) -> Option<Item<'_>> {
        Some(item!(framers.apt.next_item()?, AptItem, Some))
    }

    #[inline]
    fn frame<E>(
        track: &mut Track,
        state: usize,
        meta: Meta,
        raw: RawFrame<'_>,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<bool, E> {
        let t = Table::global();
        // Used where it was returned: copying it out would read words just stored by other
        // widths (a store-forwarding stall per frame).
        let decoded = AptFrame::decode(t, raw.offset, raw.bytes, raw.truncated);
        let Some(f) = decoded.as_ref() else {
            return Ok(false);
        };
        let (stream, pinfo) = (meta.stream, &mut track.pinfo);
        track.pairers[state]
            .1
            .observe(t, meta.n, f, meta.cap_dir, meta.ts_ns, pinfo);
        track.expired.extend(pinfo.expired.iter().map(|u| NoReply {
            proto: Proto::Apt,
            stream,
            n: u.n,
            offset: u.offset,
            name: u.name,
        }));
        let (scale, notice) = track.units.observe(stream, f);
        if let Some(nt) = notice {
            // Before the frame: what its values are converted with.
            emit(&Record::Units(&nt))?;
        }
        track.frames += 1;
        emit(&Record::Apt(AptRec {
            meta,
            frame: f,
            pair: pinfo,
            scale,
        }))?;
        Ok(true)
    }
}

/// Elliptec: the bus pairs commands with replies and flags unsolicited replies.
struct EllSide;

impl Framer for EllSide {
    const PROTO: Proto = Proto::Elliptec;

    fn state(track: &mut Track, stream: u32) -> usize {
        let timeout_ns = track.reply_timeout;
        slot(&mut track.buses, stream, || {
            let mut b = Bus::new();
            b.timeout_ns = timeout_ns;
            b
        })
    }

    #[inline]
    fn next_item(framers: &mut Framers) -> Option<Item<'_>> {
        // The Elliptec framer's kinds of garbage are not reported.
        Some(item!(framers.ell.next_item()?, EllItem, |_| None))
    }

    #[inline]
    fn frame<E>(
        track: &mut Track,
        state: usize,
        meta: Meta,
        raw: RawFrame<'_>,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<bool, E> {
        let Some(mut f) = EllFrame::decode(raw.offset, raw.bytes, raw.truncated) else {
            return Ok(false);
        };
        let o = track.buses[state].1.observe(meta.n, &f, meta.ts_ns);
        if o.unsolicited {
            f.push_diag(Diag {
                offset: raw.offset,
                kind: DiagKind::Unsolicited,
            });
        }
        let stream = meta.stream;
        track
            .expired
            .extend(o.expired.iter().map(|e| ell_no_reply(stream, e)));
        track.frames += 1;
        emit(&Record::Ell(EllRec {
            meta,
            frame: &f,
            obs: &o,
        }))?;
        Ok(true)
    }
}

fn ell_no_reply(stream: u32, e: &Expired) -> NoReply {
    NoReply {
        proto: Proto::Elliptec,
        stream,
        n: e.n,
        offset: e.offset,
        name: e.code,
    }
}

fn emit_held<E>(h: &Held, emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>) -> Result<(), E> {
    match h {
        Held::Input(d) => emit(&Record::Input(*d)),
        Held::File { offset, kind, msg } => emit(&Record::FileDiag {
            offset: *offset,
            kind,
            msg,
        }),
    }
}
