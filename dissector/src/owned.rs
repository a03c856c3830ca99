//! Records that outlive the [`Decoder`](crate::record::Decoder)'s callback: a [`Batch`] keeps a
//! run of records in an owned, compact form and hands them back as [`Record`]s, equal to those it
//! was given, on another thread or later.
//!
//! Frames keep their bytes (copied into one buffer per batch) and what the stateful part of the
//! chain learnt about them (number, time, pairing, units, the Elliptec module); the typed frame
//! itself is decoded again from its bytes when the record is read back, which is pure and costs
//! less than copying it out of the decoder (a decoded frame borrows the framer's buffer). So the
//! sequential part of a decode (framing, pairing, units, numbering) can run on one thread while
//! others render what it found.

use crate::apt::{AptFrame, GarbageKind};
use crate::detect::{Detection, Proto};
use crate::diag::{Diag, DiagKind};
use crate::ell::{EllFrame, Observation};
use crate::pair::PairInfo;
use crate::record::{AptRec, EllRec, GarbageRec, Meta, NoReply, Record};
use crate::units::{Notice, Scale};
use crate::Table;

/// A run of records, owned.
#[derive(Default)]
pub struct Batch {
    /// The bytes of every frame and garbage run, one after the other.
    bytes: Vec<u8>,
    recs: Vec<Owned>,
    /// The distinct conversions the frames refer to (by index).
    scales: Vec<Scale>,
    /// What pairing found about APT frames, those it found more about than [`COMMON`] says, and
    /// what the bus made of Elliptec frames: apart, so a record is 104 bytes, not 216 (a run
    /// of a row group's records and the runs in flight were 14 MiB each, in pages touched).
    pairs: Vec<PairInfo>,
    obs: Vec<Observation>,
}

/// What pairing found about most frames, kept once rather than per frame: nothing; or that
/// no request asked for it (what a log of a device's replies is made of: a pairing of each
/// in a run was 4 MiB of a status log's 17).
static COMMON: [PairInfo; 2] = [
    PairInfo {
        pair: None,
        latency_ns: None,
        other_address: false,
        unsolicited: false,
        duplicate: false,
        expired: Vec::new(),
        not_for_model: None,
    },
    PairInfo {
        pair: None,
        latency_ns: None,
        other_address: false,
        unsolicited: true,
        duplicate: false,
        expired: Vec::new(),
        not_for_model: None,
    },
];

/// Where a frame's or garbage run's bytes are in [`Batch::bytes`].
#[derive(Clone, Copy)]
struct Span {
    at: usize,
    len: usize,
}

enum Owned {
    Detect {
        proto: Proto,
        detection: Detection,
        sample: usize,
    },
    Stream {
        id: u32,
        name: String,
        settings: Option<String>,
    },
    Input(Diag),
    FileDiag {
        offset: u64,
        kind: String,
        msg: String,
    },
    Units(Box<Notice>),
    Apt {
        meta: Meta,
        offset: u64,
        span: Span,
        truncated: bool,
        /// One of [`COMMON`], or past them in [`Batch::pairs`].
        pair: u32,
        scale: Option<u32>,
    },
    Ell {
        meta: Meta,
        offset: u64,
        span: Span,
        truncated: bool,
        /// In [`Batch::obs`].
        obs: u32,
    },
    Garbage {
        meta: Meta,
        proto: Proto,
        offset: u64,
        span: Span,
        kind: Option<GarbageKind>,
    },
    NoReply(NoReply),
}

impl Batch {
    /// An empty batch.
    pub fn new() -> Batch {
        Batch::default()
    }

    /// Records held.
    pub fn len(&self) -> usize {
        self.recs.len()
    }

    /// Whether it holds no record.
    pub fn is_empty(&self) -> bool {
        self.recs.is_empty()
    }

    /// Bytes of frames and garbage held (with [`len`](Self::len), what says a batch is full).
    pub fn byte_len(&self) -> usize {
        self.bytes.len()
    }

    /// Make room for `records` records and `bytes` bytes of frames and garbage in all.
    pub fn reserve(&mut self, records: usize, bytes: usize) {
        self.recs.reserve(records.saturating_sub(self.recs.len()));
        self.bytes.reserve(bytes.saturating_sub(self.bytes.len()));
    }

    fn keep_bytes(&mut self, b: &[u8]) -> Span {
        let at = self.bytes.len();
        self.bytes.extend_from_slice(b);
        Span { at, len: b.len() }
    }

    /// Keep a copy of `rec`.
    pub fn push(&mut self, rec: &Record<'_>) {
        let o = match rec {
            Record::Detect {
                proto,
                detection,
                sample,
            } => Owned::Detect {
                proto: *proto,
                detection: *detection,
                sample: *sample,
            },
            Record::Stream { id, name, settings } => Owned::Stream {
                id: *id,
                name: name.to_string(),
                settings: settings.map(str::to_string),
            },
            Record::Input(d) => Owned::Input(*d),
            Record::FileDiag { offset, kind, msg } => Owned::FileDiag {
                offset: *offset,
                kind: kind.to_string(),
                msg: msg.to_string(),
            },
            Record::Units(n) => Owned::Units(Box::new((*n).clone())),
            Record::Apt(a) => {
                // The conversion of a device changes rarely: frames share one copy (equal
                // revisions are equal scales), looked for among the last few kept, as the
                // devices of a bus take turns (not all: a stream changing scales at every frame
                // would make that quadratic).
                let n = self.scales.len();
                let scale = a.scale.map(|s| {
                    let mut seen = self.scales.iter().rev().take(8);
                    match seen.position(|l| l.revision() == s.revision()) {
                        Some(back) => index(n - 1 - back),
                        None => {
                            self.scales.push(s.clone());
                            index(n)
                        }
                    }
                });
                let pair = match COMMON.iter().position(|c| c == a.pair) {
                    Some(i) => index(i),
                    None => {
                        self.pairs.push(a.pair.clone());
                        index(COMMON.len() + self.pairs.len() - 1)
                    }
                };
                let truncated = a.frame.has_diags()
                    && a.frame
                        .diags()
                        .any(|d| matches!(d.kind, DiagKind::Truncated { .. }));
                Owned::Apt {
                    meta: a.meta,
                    offset: a.frame.offset,
                    span: self.keep_bytes(a.frame.bytes),
                    truncated,
                    pair,
                    scale,
                }
            }
            Record::Ell(e) => Owned::Ell {
                meta: e.meta,
                offset: e.frame.offset,
                span: self.keep_bytes(e.frame.bytes),
                truncated: e
                    .frame
                    .diags()
                    .iter()
                    .any(|d| matches!(d.kind, DiagKind::Truncated { .. })),
                obs: {
                    self.obs.push(e.obs.clone());
                    index(self.obs.len() - 1)
                },
            },
            Record::Garbage(g) => Owned::Garbage {
                meta: g.meta,
                proto: g.proto,
                offset: g.offset,
                span: self.keep_bytes(g.bytes),
                kind: g.kind,
            },
            Record::NoReply(n) => Owned::NoReply(*n),
        };
        self.recs.push(o);
    }

    /// Pass each record, in order and as it was pushed, to `f`; stops at its first error.
    pub fn for_each<E>(&self, f: &mut impl FnMut(&Record<'_>) -> Result<(), E>) -> Result<(), E> {
        for o in &self.recs {
            self.pass(o, f)?;
        }
        Ok(())
    }

    /// Pass record `i` (in the order pushed) to `f`; nothing when there is none.
    pub fn with<E>(
        &self,
        i: usize,
        f: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        match self.recs.get(i) {
            Some(o) => self.pass(o, f),
            None => Ok(()),
        }
    }

    /// Pass the record `o` keeps to `f`.
    fn pass<E>(
        &self,
        o: &Owned,
        f: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        let bytes = |s: &Span| self.bytes.get(s.at..s.at + s.len).unwrap_or_default();
        match o {
            Owned::Detect {
                proto,
                detection,
                sample,
            } => f(&Record::Detect {
                proto: *proto,
                detection: *detection,
                sample: *sample,
            })?,
            Owned::Stream { id, name, settings } => f(&Record::Stream {
                id: *id,
                name,
                settings: settings.as_deref(),
            })?,
            Owned::Input(d) => f(&Record::Input(*d))?,
            Owned::FileDiag { offset, kind, msg } => f(&Record::FileDiag {
                offset: *offset,
                kind,
                msg,
            })?,
            Owned::Units(n) => f(&Record::Units(n))?,
            Owned::Apt {
                meta,
                offset,
                span,
                truncated,
                pair,
                scale,
            } => {
                // It decoded when it was pushed, and decoding is pure.
                let Some(frame) =
                    AptFrame::decode(Table::global(), *offset, bytes(span), *truncated)
                else {
                    return Ok(());
                };
                let i = *pair as usize;
                let pair = COMMON.get(i).or_else(|| self.pairs.get(i - COMMON.len()));
                f(&Record::Apt(AptRec {
                    meta: *meta,
                    frame: &frame,
                    pair: pair.unwrap_or(&COMMON[0]),
                    scale: scale.and_then(|i| self.scales.get(i as usize)),
                }))?
            }
            Owned::Ell {
                meta,
                offset,
                span,
                truncated,
                obs,
            } => {
                let (Some(mut frame), Some(obs)) = (
                    EllFrame::decode(*offset, bytes(span), *truncated),
                    self.obs.get(*obs as usize),
                ) else {
                    return Ok(());
                };
                // As the decoder adds it (see record.rs, EllSide::frame).
                if obs.unsolicited {
                    frame.push_diag(Diag {
                        offset: *offset,
                        kind: DiagKind::Unsolicited,
                    });
                }
                f(&Record::Ell(EllRec {
                    meta: *meta,
                    frame: &frame,
                    obs,
                }))?
            }
            Owned::Garbage {
                meta,
                proto,
                offset,
                span,
                kind,
            } => f(&Record::Garbage(GarbageRec {
                meta: *meta,
                proto: *proto,
                offset: *offset,
                bytes: bytes(span),
                kind: *kind,
            }))?,
            Owned::NoReply(n) => f(&Record::NoReply(*n))?,
        }
        Ok(())
    }

    /// Empty it, keeping its buffers.
    pub fn clear(&mut self) {
        self.bytes.clear();
        self.recs.clear();
        self.scales.clear();
        self.pairs.clear();
        self.obs.clear();
    }
}

/// A place in one of a batch's vectors (a batch holds far fewer than 2³² records).
fn index(i: usize) -> u32 {
    u32::try_from(i).unwrap_or(u32::MAX)
}
