//! APT request/reply pairing, derived from the message table: each REQ_x knows its GET_x, each
//! command knows what completes it (`reply=` in the table: MOVE_ABSOLUTE → MOVE_COMPLETED or
//! MOVE_STOPPED, MOVE_HOME → MOVE_HOMED …). Replies are matched to the oldest pending request
//! expecting them, from the address the request went to (falling back to any address: a rack may
//! answer from another bay) and on the same channel when both name one. Status updates are never
//! "unsolicited": after HW_START_UPDATEMSGS they come by design.

use crate::apt::AptFrame;
use crate::apt::Value;
use crate::diag::{Diag, DiagKind};
use crate::hash::NumMap;
use crate::msg;
use crate::table::{Class, DeviceProfile, Dir, MsgDef, Table, DEFAULT_TIMEOUT_MS};
use std::collections::{BTreeSet, VecDeque};

/// A request still waiting.
#[derive(Debug, Clone)]
struct Pending {
    n: u64,
    offset: u64,
    ts: Option<u64>,
    name: &'static str,
    id: u16,
    expects: Expects,
    device: u8,
    chan: Option<i64>,
    timeout_ns: u64,
    /// `class=stop` (see [`Waiting::stop`]).
    stop: bool,
}

/// Most replies a request can have (the table's `reply=` lists name at most two, plus GET_x for
/// REQ_x; a table test checks the bound).
pub const MAX_REPLIES: usize = 4;

/// The ids of the messages that answer a request, kept inline (no allocation per request).
#[derive(Debug, Clone, Copy)]
struct Expects {
    ids: [u16; MAX_REPLIES],
    len: u8,
}

impl Expects {
    fn new(ids: &[u16]) -> Self {
        let mut e = Expects {
            ids: [0; MAX_REPLIES],
            len: 0,
        };
        for (slot, id) in e.ids.iter_mut().zip(ids) {
            *slot = *id;
            e.len += 1;
        }
        e
    }
    fn as_slice(&self) -> &[u16] {
        &self.ids[..usize::from(self.len)]
    }
}

/// A request answered recently (to recognise duplicate replies).
#[derive(Debug, Clone, Copy)]
struct Answered {
    n: u64,
    reply_id: u16,
    device: u8,
    chan: Option<i64>,
}

/// A request that got no reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unanswered {
    /// Record number of the request.
    pub n: u64,
    /// Its stream offset.
    pub offset: u64,
    /// Its name.
    pub name: &'static str,
}

/// What pairing made of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PairInfo {
    /// Record number of the request this frame answers.
    pub pair: Option<u64>,
    /// Time from the request to this reply.
    pub latency_ns: Option<u64>,
    /// The reply came from another address than the request went to.
    pub other_address: bool,
    /// A reply no pending request expected (status updates and error reports excepted).
    pub unsolicited: bool,
    /// A second reply to a request that was already answered.
    pub duplicate: bool,
    /// Requests whose timeout passed before this frame.
    pub expired: Vec<Unanswered>,
    /// The device's model (named earlier by its HW_GET_INFO) does not implement this message,
    /// according to the spec's device lists.
    pub not_for_model: Option<[u8; 8]>,
}

impl PairInfo {
    /// The diagnostics pairing adds to a frame at `offset`: `unsolicited`, `duplicate_reply`,
    /// `not_for_model`.
    pub fn diags(&self, offset: u64) -> impl Iterator<Item = Diag> {
        let kinds = [
            self.unsolicited.then_some(DiagKind::Unsolicited),
            self.pair
                .filter(|_| self.duplicate)
                .map(|request| DiagKind::DuplicateReply { request }),
            self.not_for_model
                .map(|model| DiagKind::NotForModel { model }),
        ];
        kinds
            .into_iter()
            .flatten()
            .map(move |kind| Diag { offset, kind })
    }
}

/// Bound on requests waiting (a device that never answers must not grow memory). High enough
/// that a host flooding requests faster than the line answers keeps its pairing: past it, the
/// oldest is given up and every later reply would pair one request too late.
const MAX_PENDING: usize = 4096;
const RECENT: usize = 64;
// `recent_keys` counts in a u8.
const _: () = assert!(RECENT < 256);

/// How long a request waits for its reply: the table's `timeout=` (motion waits for the end of
/// the move), else [`DEFAULT_TIMEOUT_MS`] (the spec gives none; requests are answered within
/// milliseconds).
pub fn default_timeout_ns(m: &MsgDef) -> u64 {
    u64::from(m.timeout_ms.unwrap_or(DEFAULT_TIMEOUT_MS)) * 1_000_000
}

/// Messages that come by design, not as a reply: status streams (after HW_START_UPDATEMSGS)
/// and what a device sends on its own (the table's `class=status` / `class=spontaneous`).
fn comes_unasked(m: &MsgDef) -> bool {
    m.class.has(Class::STATUS) || m.class.has(Class::SPONTANEOUS)
}

/// Take request `n` out of the list under `key`.
fn drop_waiting<K: std::hash::Hash + Eq>(lists: &mut NumMap<K, VecDeque<Waiting>>, key: K, n: u64) {
    if let Some(v) = lists.get_mut(&key) {
        // Requests are mostly answered in order: at or near the front.
        if let Some(i) = v.iter().position(|w| w.n == n) {
            v.remove(i);
        }
        // An emptied list is kept (its key usually comes back: no allocation per request);
        // `insert` sweeps them when there are many.
    }
}

/// Lists of `by_chan` kept, empty ones included, before the empty ones are swept: twice the
/// most that can hold requests, so that a sweep frees at least half (sweeps stay rare).
const LISTS_KEPT: usize = 2 * MAX_REPLIES * MAX_PENDING;

/// A channel as a key of `by_chan` (requests naming no channel under one that no channel
/// number takes).
fn chan_key(chan: Option<i64>) -> i64 {
    chan.unwrap_or(i64::MIN)
}

/// In a list of waiting requests, oldest first: the oldest to `device` and the oldest of all,
/// among the first [`SCAN`].
fn oldest_in(list: Option<&VecDeque<Waiting>>, device: u8) -> (Option<u64>, Option<u64>) {
    let Some(list) = list else {
        return (None, None);
    };
    let to = list.iter().take(SCAN).find(|w| w.device == device);
    (to.map(|w| w.n), list.front().map(|w| w.n))
}

/// The bucket of `recent_keys` for a reply id from a device (ids sharing a bucket only cost a
/// look at `recent`).
fn recent_key(id: u16, device: u8) -> usize {
    usize::from(id ^ (u16::from(device) << 8))
}

/// A waiting request as a reply sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Waiting {
    n: u64,
    device: u8,
    chan: Option<i64>,
    /// The request's message id.
    id: u16,
    /// The request stops a move (`class=stop`): each stop is answered by its own end-of-move
    /// reply, not swept up by another's.
    stop: bool,
}

/// How many of the oldest waiting requests a reply looks at: replies come in order, so its
/// request is at the front; a bound keeps a flood of unanswered requests (a capture of one
/// direction) from making each reply a scan of thousands.
const SCAN: usize = 256;

/// APT pairing state for one stream.
#[derive(Debug, Default)]
pub struct AptPairer {
    /// Waiting requests by record number.
    pending: NumMap<u64, Pending>,
    /// Record numbers of the waiting requests, oldest first; those answered since are dropped
    /// when they reach the front (or when they are most of the list).
    order: VecDeque<u64>,
    /// The waiting requests that expect each message id, oldest first, with what a reply is
    /// matched on: a reply looks only at the requests it can answer, without map lookups.
    by_reply: NumMap<u16, VecDeque<Waiting>>,
    /// The same requests by (reply id, [`chan_key`] of their channel): a reply naming a
    /// channel looks only at the requests on it and those naming none, not at every other
    /// channel's.
    by_chan: NumMap<(u16, i64), VecDeque<Waiting>>,
    /// Waiting requests with a time, by the time they expire (the timeout fixed when they came).
    deadlines: BTreeSet<(u64, u64)>,
    recent: VecDeque<Answered>,
    /// How many of `recent` each (reply id, device) bucket has ([`recent_key`]): most replies
    /// nobody waited for have none, and need no look at `recent`.
    recent_keys: Vec<u8>,
    /// What each device address (by its HW_GET_INFO) implements, by address (empty until a
    /// device names its model).
    models: Vec<Option<([u8; 8], Option<DeviceProfile>)>>,
    /// Overrides the per-message default timeout.
    pub timeout_ns: Option<u64>,
    /// Scratch list of the other requests a reply also answers (reused, not allocated per reply).
    also: Vec<u64>,
}

impl AptPairer {
    /// A pairer with the default timeouts.
    pub fn new() -> Self {
        Self::default()
    }

    fn insert(&mut self, p: Pending) {
        let w = Waiting {
            n: p.n,
            device: p.device,
            chan: p.chan,
            id: p.id,
            stop: p.stop,
        };
        if self.by_chan.len() >= LISTS_KEPT {
            self.by_chan.retain(|_, v| !v.is_empty());
        }
        for id in p.expects.as_slice() {
            self.by_reply.entry(*id).or_default().push_back(w);
            self.by_chan
                .entry((*id, chan_key(p.chan)))
                .or_default()
                .push_back(w);
        }
        if let Some(d) = self.deadline(&p) {
            self.deadlines.insert((d, p.n));
        }
        self.order.push_back(p.n);
        self.pending.insert(p.n, p);
        if self.order.len() > 2 * self.pending.len() + 1024 {
            let pending = &self.pending;
            self.order.retain(|n| pending.contains_key(n));
        }
    }

    fn remove(&mut self, n: u64) -> Option<Pending> {
        let p = self.pending.remove(&n)?;
        if let Some(d) = self.deadline(&p) {
            self.deadlines.remove(&(d, n));
        }
        for &id in p.expects.as_slice() {
            drop_waiting(&mut self.by_reply, id, n);
            drop_waiting(&mut self.by_chan, (id, chan_key(p.chan)), n);
        }
        Some(p)
    }

    /// The oldest waiting request.
    fn oldest(&mut self) -> Option<u64> {
        while let Some(&n) = self.order.front() {
            if self.pending.contains_key(&n) {
                return Some(n);
            }
            self.order.pop_front();
        }
        None
    }

    /// When a waiting request expires, if it has a time.
    fn deadline(&self, p: &Pending) -> Option<u64> {
        p.ts.map(|t| t.saturating_add(self.timeout_ns.unwrap_or(p.timeout_ns)))
    }

    fn expire(&mut self, now: Option<u64>, out: &mut Vec<Unanswered>) {
        let Some(now) = now else { return };
        while let Some(&(d, n)) = self.deadlines.first() {
            if d >= now {
                break;
            }
            self.deadlines.pop_first();
            if let Some(p) = self.remove(n) {
                out.push(Unanswered {
                    n: p.n,
                    offset: p.offset,
                    name: p.name,
                });
            }
        }
    }

    /// Observe frame `n` (time of its first byte `ts`; `dir` when the capture records it): what
    /// pairing made of it goes into `info` (overwritten; its `expired` keeps its allocation, so
    /// a decoder reuses one for every frame). The steps: expire what waited too long, check the
    /// message against the device's model, then a request waits for its reply, and a reply is
    /// matched to its request or else told a duplicate or unsolicited.
    pub fn observe(
        &mut self,
        table: &Table,
        n: u64,
        f: &AptFrame<'_, '_>,
        dir: Option<Dir>,
        ts: Option<u64>,
        info: &mut PairInfo,
    ) {
        let mut expired = std::mem::take(&mut info.expired);
        expired.clear();
        *info = PairInfo {
            expired,
            ..PairInfo::default()
        };
        self.expire(ts, &mut info.expired);
        let Some(m) = f.msg else { return };
        let h = f.header();
        let chan = f.channel();
        let from_host = match dir {
            Some(d) => d == Dir::HostToDevice,
            None => m.dir != Dir::DeviceToHost && h.src_byte() == 0x01,
        };
        self.check_model(
            table,
            f,
            m,
            if from_host {
                h.dst_byte()
            } else {
                h.src_byte()
            },
            info,
        );
        if from_host {
            let expects = table.reply_ids(m);
            if !expects.is_empty() && !self.silent(table, h.dst_byte(), m.id) {
                let p = Pending {
                    n,
                    offset: f.offset,
                    ts,
                    name: m.name,
                    id: m.id,
                    expects: Expects::new(expects),
                    device: h.dst_byte(),
                    chan,
                    timeout_ns: default_timeout_ns(m),
                    stop: m.class.has(Class::STOP),
                };
                self.wait(p, info);
            }
            return;
        }
        let src = h.src_byte();
        match self.take_request(m, src, chan) {
            Some(p) => self.answer(table, m, p, src, ts, info),
            None => self.duplicate(m, src, chan, info),
        }
    }

    /// A request waits for its replies (the oldest waiting one given up when too many wait).
    fn wait(&mut self, p: Pending, info: &mut PairInfo) {
        if self.pending.len() >= MAX_PENDING {
            if let Some(old) = self.oldest().and_then(|k| self.remove(k)) {
                info.expired.push(Unanswered {
                    n: old.n,
                    offset: old.offset,
                    name: old.name,
                });
            }
        }
        self.insert(p);
    }

    /// The request a reply `m` from address `src` on `chan` answers, taken from the waiting
    /// ones: the oldest usable request (on the reply's channel, or naming none; any when the
    /// reply names none) to the replying address, else the oldest usable one.
    fn take_request(&mut self, m: &MsgDef, src: u8, chan: Option<i64>) -> Option<Pending> {
        let (found, any) = match chan {
            None => oldest_in(self.by_reply.get(&m.id), src),
            Some(c) => {
                let (f1, a1) = oldest_in(self.by_chan.get(&(m.id, c)), src);
                let (f2, a2) = oldest_in(self.by_chan.get(&(m.id, chan_key(None))), src);
                let older = |a: Option<u64>, b: Option<u64>| match (a, b) {
                    (Some(x), Some(y)) => Some(x.min(y)),
                    (x, y) => x.or(y),
                };
                (older(f1, f2), older(a1, a2))
            }
        };
        found.or(any).and_then(|k| self.remove(k))
    }

    /// Reply `m` from `src` answers request `p`: the other requests it also ends are dropped,
    /// the pair goes into `info` and is remembered for [`AptPairer::duplicate`].
    fn answer(
        &mut self,
        table: &Table,
        m: &MsgDef,
        p: Pending,
        src: u8,
        ts: Option<u64>,
        info: &mut PairInfo,
    ) {
        self.sweep(table, m, &p);
        info.pair = Some(p.n);
        info.other_address = p.device != src;
        info.latency_ns = match (p.ts, ts) {
            (Some(a), Some(b)) => Some(b.saturating_sub(a)),
            _ => None,
        };
        if self.recent_keys.is_empty() {
            self.recent_keys = vec![0; 1 << 16];
        }
        if self.recent.len() == RECENT {
            if let Some(old) = self.recent.pop_front() {
                let c = &mut self.recent_keys[recent_key(old.reply_id, old.device)];
                *c = c.saturating_sub(1);
            }
        }
        self.recent_keys[recent_key(m.id, p.device)] += 1;
        self.recent.push_back(Answered {
            n: p.n,
            reply_id: m.id,
            device: p.device,
            chan: p.chan,
        });
    }

    /// The other requests reply `m` also ends besides `p`, dropped.
    fn sweep(&mut self, table: &Table, m: &MsgDef, p: &Pending) {
        // Requests are answered first in, first out per (device, channel, reply). An
        // end-of-move reply (`class=end_of_move`) also ends what the move it reports
        // superseded: the other moves waiting on that device and channel (one
        // MOVE_COMPLETED ends a move and the moves sent over it) and, when it answers a
        // move, the oldest stop that ended it (MOVE_STOPPED completes a move and its
        // stop). A stop is never swept by another stop's reply: a host that stops twice
        // (thorlabs-apt-device's `close()` does) gets a MOVE_STOPPED for each. Any other
        // reply (a GET) answers one request: repeated requests wait for their own.
        let end_of_move = m.class.has(Class::END_OF_MOVE);
        let mut also = std::mem::take(&mut self.also);
        also.clear();
        // A reply only one kind of request expects answers one request of that kind.
        let several = end_of_move || table.requesters(m) > 1;
        if let Some(v) = self.by_reply.get(&m.id).filter(|_| several) {
            let mut stop_taken = p.stop;
            for q in v.iter().take(SCAN) {
                if q.device != p.device || q.chan != p.chan || q.n == p.n {
                    continue;
                }
                let take = if !end_of_move {
                    q.id != p.id
                } else if p.stop {
                    false
                } else if q.stop {
                    !std::mem::replace(&mut stop_taken, true)
                } else {
                    true
                };
                if take {
                    also.push(q.n);
                }
            }
        }
        for &k in &also {
            self.remove(k);
        }
        self.also = also;
    }

    /// A reply no waiting request expects: a repeat of a reply already paired (the same id
    /// from the same device, on a channel that fits), else unsolicited (a status update that
    /// comes unasked is neither).
    fn duplicate(&self, m: &MsgDef, src: u8, chan: Option<i64>, info: &mut PairInfo) {
        let chan_ok = |c: Option<i64>| c.is_none() || chan.is_none() || c == chan;
        if comes_unasked(m) {
            return;
        }
        let seen = self
            .recent_keys
            .get(recent_key(m.id, src))
            .is_some_and(|&c| c > 0);
        match seen
            .then(|| {
                self.recent
                    .iter()
                    .rev()
                    .find(|a| a.reply_id == m.id && a.device == src && chan_ok(a.chan))
            })
            .flatten()
        {
            Some(a) => {
                info.pair = Some(a.n);
                info.duplicate = true;
            }
            None => info.unsolicited = true,
        }
    }

    /// Learn a device's model from its HW_GET_INFO; flag messages its model does not implement.
    fn check_model(
        &mut self,
        table: &Table,
        f: &AptFrame<'_, '_>,
        m: &MsgDef,
        device: u8,
        info: &mut PairInfo,
    ) {
        // HW_GET_INFO names the device's model.
        if m.id == msg::HW_GET_INFO {
            let model = f.field("model_number").and_then(|(_, v)| match v {
                Value::Str(b) => Some(b),
                _ => None,
            });
            if let Some(b) = model {
                let mut name = [0u8; 8];
                let end = b.iter().position(|&c| c == 0).unwrap_or(b.len()).min(8);
                name[..end].copy_from_slice(&b[..end]);
                if self.models.is_empty() {
                    self.models.resize(256, None);
                }
                let slot = &mut self.models[usize::from(device)];
                // A device answers HW_REQ_INFO with the same model each time: its profile (a
                // walk over the whole table) is worked out once, not for every answer.
                if !matches!(slot, Some((n, _)) if *n == name) {
                    let text = String::from_utf8_lossy(&name[..end]).into_owned();
                    *slot = Some((name, table.device_profile(&text)));
                }
            }
            return;
        }
        if let Some(Some((name, Some(p)))) = self.models.get(usize::from(device)) {
            if !table.implements(p, m.id) {
                info.not_for_model = Some(*name);
            }
        }
    }

    /// Whether the model `device` named in HW_GET_INFO sends no reply to message `id` (a
    /// `silent` line of its table profile).
    fn silent(&self, table: &Table, device: u8, id: u16) -> bool {
        matches!(
            self.models.get(usize::from(device)),
            Some(Some((_, Some(p)))) if !table.answers(p, id)
        )
    }

    /// End of stream: every request still waiting got no reply.
    pub fn finish(&mut self) -> Vec<Unanswered> {
        self.by_reply.clear();
        self.by_chan.clear();
        self.deadlines.clear();
        self.order.clear();
        let mut left: Vec<Pending> = std::mem::take(&mut self.pending).into_values().collect();
        left.sort_unstable_by_key(|p| p.n);
        left.into_iter()
            .map(|p| Unanswered {
                n: p.n,
                offset: p.offset,
                name: p.name,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn observe(
        p: &mut AptPairer,
        t: &Table,
        n: u64,
        f: &AptFrame<'_, '_>,
        dir: Option<Dir>,
        ts: Option<u64>,
    ) -> PairInfo {
        let mut info = PairInfo::default();
        p.observe(t, n, f, dir, ts, &mut info);
        info
    }
    use crate::apt::{encode, FieldValue};

    fn frame(
        table: &Table,
        name: &str,
        vals: &[(&str, i64)],
        dst: u8,
        src: u8,
        data: bool,
    ) -> Vec<u8> {
        let m = table.msg_by_name(name).expect("message");
        let form = m
            .forms
            .iter()
            .find(|f| matches!(f.kind, crate::table::FormKind::Data(_)) == data)
            .expect("form");
        let v: Vec<(&str, FieldValue)> = vals
            .iter()
            .map(|(k, x)| (*k, FieldValue::Int(*x)))
            .collect();
        encode(form, &v, m.id, dst, src).expect("encode")
    }

    #[test]
    fn pairs_across_interleaved_status_updates_and_bays() {
        let t = Table::global();
        let mut p = AptPairer::new();
        let frames = [
            frame(
                t,
                "MOT_MOVE_ABSOLUTE",
                &[("chan_ident", 1), ("absolute_position", 1000)],
                0x21,
                0x01,
                true,
            ),
            frame(
                t,
                "MOT_REQ_VELPARAMS",
                &[("chan_ident", 1)],
                0x22,
                0x01,
                false,
            ),
            frame(
                t,
                "MOT_GET_DCSTATUSUPDATE",
                &[("chan_ident", 1)],
                0x01,
                0x21,
                true,
            ),
            frame(
                t,
                "MOT_GET_VELPARAMS",
                &[("chan_ident", 1)],
                0x01,
                0x22,
                true,
            ),
            frame(
                t,
                "MOT_GET_DCSTATUSUPDATE",
                &[("chan_ident", 1)],
                0x01,
                0x21,
                true,
            ),
            frame(
                t,
                "MOT_MOVE_COMPLETED",
                &[("chan_ident", 1)],
                0x01,
                0x21,
                true,
            ),
            frame(
                t,
                "MOT_MOVE_COMPLETED",
                &[("chan_ident", 1)],
                0x01,
                0x21,
                true,
            ),
            frame(
                t,
                "MOT_GET_VELPARAMS",
                &[("chan_ident", 1)],
                0x01,
                0x23,
                true,
            ),
        ];
        let infos: Vec<PairInfo> = frames
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let f = AptFrame::decode(t, 0, b, false).expect("frame");
                observe(
                    &mut p,
                    t,
                    i as u64 + 1,
                    &f,
                    None,
                    Some(i as u64 * 1_000_000),
                )
            })
            .collect();
        assert_eq!(
            infos[2],
            PairInfo::default(),
            "a status update between is neither paired nor flagged"
        );
        assert_eq!(
            infos[3].pair,
            Some(2),
            "GET_VELPARAMS from bay 1 answers REQ_VELPARAMS to bay 1"
        );
        assert_eq!(infos[3].latency_ns, Some(2_000_000));
        assert_eq!(
            infos[5].pair,
            Some(1),
            "MOVE_COMPLETED completes MOVE_ABSOLUTE"
        );
        assert!(
            infos[6].duplicate && infos[6].pair == Some(1),
            "a second MOVE_COMPLETED is a duplicate"
        );
        assert!(infos[7].unsolicited, "GET_VELPARAMS nobody asked for");
        assert!(p.finish().is_empty());
    }

    #[test]
    fn unanswered_requests_expire_by_time_or_at_the_end() {
        let t = Table::global();
        let mut p = AptPairer::new();
        let req = frame(t, "HW_REQ_INFO", &[], 0x50, 0x01, false);
        let f = AptFrame::decode(t, 0, &req, false).expect("frame");
        observe(&mut p, t, 1, &f, None, Some(0));
        observe(&mut p, t, 2, &f, None, Some(1_000_000_000));
        let later = frame(t, "MOD_IDENTIFY", &[], 0x50, 0x01, false);
        let g = AptFrame::decode(t, 12, &later, false).expect("frame");
        let info = observe(&mut p, t, 3, &g, None, Some(2_500_000_000));
        assert_eq!(info.expired.iter().map(|u| u.n).collect::<Vec<_>>(), [1]);
        assert_eq!(
            p.finish().iter().map(|u| (u.n, u.name)).collect::<Vec<_>>(),
            [(2, "HW_REQ_INFO")]
        );
    }

    /// A host flooding requests (a thousand waiting at once) keeps every reply paired with its
    /// own request, in order.
    #[test]
    fn a_reply_finds_its_channel_behind_many_waiting_on_another() {
        let t = Table::global();
        let mut p = AptPairer::new();
        let on = |chan: i64, name: &str, host: bool| {
            let (dst, src) = if host { (0x50, 0x01) } else { (0x01, 0x50) };
            frame(t, name, &[("chan_ident", chan)], dst, src, !host)
        };
        let (q1, q2) = (
            on(1, "MOT_REQ_VELPARAMS", true),
            on(2, "MOT_REQ_VELPARAMS", true),
        );
        let r2 = on(2, "MOT_GET_VELPARAMS", false);
        let (q1, q2, r2) = (
            AptFrame::decode(t, 0, &q1, false).expect("frame"),
            AptFrame::decode(t, 0, &q2, false).expect("frame"),
            AptFrame::decode(t, 0, &r2, false).expect("frame"),
        );
        // More unanswered requests on channel 1 than a reply looks through.
        let many = SCAN as u64 + 50;
        for i in 1..=many {
            observe(&mut p, t, i, &q1, Some(Dir::HostToDevice), None);
        }
        observe(&mut p, t, many + 1, &q2, Some(Dir::HostToDevice), None);
        let info = observe(&mut p, t, many + 2, &r2, Some(Dir::DeviceToHost), None);
        assert_eq!(info.pair, Some(many + 1));
        assert!(!info.unsolicited);
        // Channel 1's requests are still waiting: the reply took only its own.
        assert_eq!(p.finish().len() as u64, many);
    }

    #[test]
    fn a_burst_of_waiting_requests_pairs_in_order() {
        let t = Table::global();
        let mut p = AptPairer::new();
        let req = frame(
            t,
            "MOT_REQ_VELPARAMS",
            &[("chan_ident", 1)],
            0x50,
            0x01,
            false,
        );
        let rep = frame(
            t,
            "MOT_GET_VELPARAMS",
            &[("chan_ident", 1)],
            0x01,
            0x50,
            true,
        );
        let (fq, fr) = (
            AptFrame::decode(t, 0, &req, false).expect("frame"),
            AptFrame::decode(t, 0, &rep, false).expect("frame"),
        );
        let n = 1000u64;
        for i in 1..=n {
            let info = observe(&mut p, t, i, &fq, Some(Dir::HostToDevice), Some(i));
            assert!(info.expired.is_empty());
        }
        for i in 1..=n {
            let info = observe(&mut p, t, n + i, &fr, Some(Dir::DeviceToHost), Some(n + i));
            assert_eq!(info.pair, Some(i));
            assert!(!info.duplicate && !info.unsolicited && info.expired.is_empty());
        }
        assert!(p.finish().is_empty());
    }
}
