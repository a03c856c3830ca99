//! The message table: every APT message described once, parsed from `dissector/msgs/*.apt`.
//!
//! Decode, encode, the `messages` listing, JSON names and the spec-example tests all read it.

mod model;
mod parse;

pub use model::*;
pub use parse::{example_bytes, parse_int, TableError, TableErrors};

use std::sync::OnceLock;

mod sources {
    include!(concat!(env!("OUT_DIR"), "/sources.rs"));
}

/// The messages one controller model implements (from the table's `devices` blocks).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceProfile {
    /// The model as the device named itself.
    pub model: String,
    /// Per message index: listed for this model.
    msgs: Box<[bool]>,
    /// Per message index: the model sends none of the replies the table names for it.
    silent: Box<[bool]>,
}

/// The parsed table with its lookup indexes.
#[derive(Debug)]
pub struct Table {
    data: TableData,
    /// Message index by id; `u16::MAX` for none.
    by_id: Box<[u16]>,
    /// Per message index: its group's sub-messages as (sub id, index into `data.subs`).
    msg_subs: Vec<Vec<(u16, usize)>>,
    /// Per message index: the ids of the messages that answer it (see [`Table::replies_of`]).
    reply_ids: Vec<Vec<u16>>,
    /// Per message index: how many messages it answers (saturating).
    requesters: Vec<u8>,
    /// Per message index: the names of the fields of its forms and sub-messages' forms.
    field_names: Vec<Vec<&'static str>>,
    /// Per message index: the lengths it exists in, for [`Table::accepts_len`] (the framer asks
    /// it of most header-only frames).
    lens: Vec<LenSet>,
    /// The lengths of the `devices` blocks' model names, as bits (63: that long or longer):
    /// a model of no such length is in no block, and [`Table::device_profile`] says so without
    /// a walk over every block (a capture of damaged or random HW_GET_INFO replies names a new
    /// model in each).
    model_lens: u64,
}

/// The bit of a model name's length in [`Table::model_lens`].
fn len_bit(model: &str) -> u64 {
    1 << model.len().min(63)
}

/// [`MsgDef::data_form`] of a message's forms: for each data packet length up to 255, the
/// first form the decoder's walk would stop at (a data or open form taking that length, or a
/// `sub` form when the packet holds a sub-message id): that form when it is a data or open
/// one, else [`DataForm::WALK`]; [`DataForm::NONE`] when there is none.
fn data_forms(forms: &[Form]) -> [DataForm; 256] {
    let mut out = [DataForm::NONE; 256];
    if forms.len() >= 0x80 {
        return [DataForm::WALK; 256];
    }
    // Last form first, so that the first that stops the walk is the one left.
    for (i, f) in forms.iter().enumerate().rev() {
        let lens = match f.kind {
            FormKind::Header => 0..0,
            FormKind::Data(k) => usize::from(k)..usize::from(k) + 1,
            FormKind::Open(_) | FormKind::Sub => 0..256,
        };
        for len in lens.filter(|&len| len < 256) {
            match f.kind {
                FormKind::Sub if len >= 2 => out[len] = DataForm::WALK,
                FormKind::Data(_) | FormKind::Open(_) if f.accepts_len(true, len) => {
                    // `i` < 0x80.
                    out[len] = DataForm(i as u8);
                }
                _ => {}
            }
        }
    }
    out
}

/// The lengths one message exists in: [`Table::accepts_len`] worked out once.
#[derive(Debug, Clone, Copy)]
struct LenSet {
    /// It has a header-only form.
    hdr: bool,
    /// Bit `n`: it has a data packet of `n` bytes, for `n` up to 255.
    data: [u64; 4],
}

impl Table {
    /// The table compiled into this library.
    ///
    /// The embedded files are checked by this crate's tests, so a failure here is a build defect,
    /// never a property of input data.
    pub fn global() -> &'static Table {
        static T: OnceLock<Table> = OnceLock::new();
        T.get_or_init(|| match Table::from_sources(sources::SOURCES) {
            Ok(t) => t,
            Err(e) => panic!("the embedded message table has errors:\n{e}"),
        })
    }

    /// The `devices` blocks: which messages each controller model implements.
    pub fn devices(&self) -> &[DeviceGroup] {
        &self.data.devices
    }

    /// The models (as the spec names them) that take `m`: their lists or a section of the spec
    /// name it, a message it answers, or a reply it asks for (as in `device_profile`), in table
    /// order.
    pub fn models_of(&self, m: &MsgDef) -> Vec<&'static str> {
        let mut out: Vec<&'static str> = vec![];
        for g in &self.data.devices {
            let named = g
                .msgs
                .iter()
                .filter_map(|n| self.msg_by_name(n))
                .any(|q| q.id == m.id || self.exchange(q, m));
            if named {
                for x in &g.models {
                    if !out.contains(x) {
                        out.push(x);
                    }
                }
            }
        }
        out
    }

    /// Whether `b` is the other half of `a`'s exchange: `a`'s reply (REQ_x → GET_x, `reply=`),
    /// or a query `a` answers (not a move or stop: MOVE_COMPLETED does not make every move a
    /// model's).
    fn exchange(&self, a: &MsgDef, b: &MsgDef) -> bool {
        let query = |m: &MsgDef| !m.class.has(Class::MOTION) && !m.class.has(Class::STOP);
        self.reply_ids(a).contains(&b.id) || (query(b) && self.reply_ids(b).contains(&a.id))
    }

    /// What a model (as an HW_GET_INFO reply names it) implements: the messages its lists
    /// (`devices` blocks) name, those the spec's message sections say apply to it (`section`
    /// blocks: the lists often leave them out, KDC101's MOT_REQ_KCUBETRIGIOCONFIG), and for each
    /// the other half of its exchange: a device that takes a request sends its reply (TTC001's
    /// list names REQ_STATUSUPDATE without GET_STATUSUPDATE), and one that sends a reply answers
    /// its request (KPZ101's lists name PZ_GET_PZSTATUSUPDATE without its REQ, which pylablib's
    /// KinesisPiezoController polls). `None` when no list names the model: nothing can be said
    /// of it then.
    pub fn device_profile(&self, model: &str) -> Option<DeviceProfile> {
        let model = model.trim();
        if self.model_lens & len_bit(model) == 0 {
            return None;
        }
        let groups: Vec<&DeviceGroup> = self
            .data
            .devices
            .iter()
            .filter(|g| g.matches_trimmed(model))
            .collect();
        if !groups.iter().any(|g| g.source == DeviceSource::List) {
            return None;
        }
        let mut msgs = vec![false; self.data.msgs.len()];
        let mut silent = vec![false; self.data.msgs.len()];
        for g in groups {
            for name in &g.silent {
                if let Some(i) = self.data.msgs.iter().position(|m| m.name == *name) {
                    silent[i] = true;
                }
            }
            for name in &g.msgs {
                let Some(i) = self.data.msgs.iter().position(|m| m.name == *name) else {
                    continue;
                };
                msgs[i] = true;
                let listed = &self.data.msgs[i];
                for (j, q) in self.data.msgs.iter().enumerate() {
                    if self.exchange(listed, q) {
                        msgs[j] = true;
                    }
                }
            }
        }
        Some(DeviceProfile {
            model: model.to_string(),
            msgs: msgs.into_boxed_slice(),
            silent: silent.into_boxed_slice(),
        })
    }

    /// Whether `profile`'s model answers message `id` with the replies the table names for it:
    /// not when a `silent` line says the model sends none (a flipper's MOT_MOVE_JOG).
    pub fn answers(&self, profile: &DeviceProfile, id: u16) -> bool {
        match self.by_id.get(id as usize) {
            Some(&i) if i != u16::MAX => !profile.silent.get(i as usize).copied().unwrap_or(false),
            _ => true,
        }
    }

    /// Whether `profile`'s model implements message `id` (unknown ids: `true`, nothing to say).
    pub fn implements(&self, profile: &DeviceProfile, id: u16) -> bool {
        match self.by_id.get(id as usize) {
            Some(&i) if i != u16::MAX => profile.msgs.get(i as usize).copied().unwrap_or(true),
            _ => true,
        }
    }

    /// The embedded table files: `(file name, text)`.
    pub fn embedded_sources() -> &'static [(&'static str, &'static str)] {
        sources::SOURCES
    }

    /// Parse table files (`(file name, text)`, in order).
    pub fn from_sources(src: &[(&'static str, &'static str)]) -> Result<Table, TableErrors> {
        let mut data = parse::parse_sources(src)?;
        let msg_forms = data.msgs.iter_mut().flat_map(|m| m.forms.iter_mut());
        let sub_forms = data.subs.iter_mut().flat_map(|s| s.forms.iter_mut());
        msg_forms.chain(sub_forms).for_each(|f| {
            f.index();
            f.idx.max_data = crate::apt::MAX_DATA_LEN as u16;
        });
        // Each form knows its message's largest packet (`maxlen=`), so its length rule
        // (`Form::accepts_len`) needs no table; a sub-message's form takes its group's largest.
        for i in 0..data.msgs.len() {
            let Some(max) = data.msgs[i].max_len else {
                continue;
            };
            let group = data.msgs[i].subs;
            for f in data.msgs[i].forms.iter_mut() {
                f.idx.max_data = max;
            }
            let subs = data.subs.iter_mut().filter(|s| Some(s.group) == group);
            for f in subs.flat_map(|s| s.forms.iter_mut()) {
                f.idx.max_data = f.idx.max_data.max(max);
            }
        }
        for m in data.msgs.iter_mut() {
            let first = m.forms.iter().position(|f| f.kind == FormKind::Header);
            m.hdr_form = first.and_then(|i| u8::try_from(i).ok());
            m.data_form = data_forms(&m.forms);
        }
        let mut by_id = vec![u16::MAX; 65536].into_boxed_slice();
        for (i, m) in data.msgs.iter().enumerate() {
            by_id[m.id as usize] = i as u16;
        }
        let msg_subs = data
            .msgs
            .iter()
            .map(|m| {
                let subs = data.subs.iter().enumerate();
                subs.filter(|(_, s)| Some(s.group) == m.subs)
                    .map(|(i, s)| (s.id, i))
                    .collect()
            })
            .collect();
        let mut t = Table {
            data,
            by_id,
            msg_subs,
            reply_ids: vec![],
            requesters: vec![],
            field_names: vec![],
            lens: vec![],
            model_lens: 0,
        };
        t.model_lens = t
            .data
            .devices
            .iter()
            .flat_map(|g| &g.models)
            .fold(0, |b, m| b | len_bit(m));
        t.lens = (0..t.data.msgs.len()).map(|i| t.len_set(i)).collect();
        t.field_names = (0..t.data.msgs.len())
            .map(|i| {
                let m = &t.data.msgs[i];
                let subs = t.msg_subs[i].iter().map(|&(_, s)| &t.data.subs[s]);
                let forms = m.forms.iter().chain(subs.flat_map(|s| s.forms.iter()));
                let mut names: Vec<&'static str> = forms
                    .flat_map(|f| f.fields.iter().map(|x| x.name))
                    .collect();
                names.sort_unstable();
                names.dedup();
                names
            })
            .collect();
        t.reply_ids = t
            .data
            .msgs
            .iter()
            .map(|m| t.replies_of(m).iter().map(|r| r.id).collect())
            .collect();
        t.requesters = vec![0; t.data.msgs.len()];
        for ids in &t.reply_ids {
            for id in ids {
                if let Some(&i) = t.by_id.get(usize::from(*id)).filter(|&&i| i != u16::MAX) {
                    if let Some(c) = t.requesters.get_mut(usize::from(i)) {
                        *c = c.saturating_add(1);
                    }
                }
            }
        }
        Ok(t)
    }

    /// All messages, in table order.
    pub fn msgs(&self) -> &[MsgDef] {
        &self.data.msgs
    }

    /// All sub-messages.
    pub fn subs(&self) -> &[SubDef] {
        &self.data.subs
    }

    /// The message with this id.
    #[inline]
    pub fn msg(&self, id: u16) -> Option<&MsgDef> {
        match self.by_id[id as usize] {
            u16::MAX => None,
            i => self.data.msgs.get(i as usize),
        }
    }

    /// The message with this name (case-insensitive, `MGMSG_` prefix optional).
    pub fn msg_by_name(&self, name: &str) -> Option<&MsgDef> {
        // Its id, as `messages 0x0453` takes it.
        if let Some(hex) = name.strip_prefix("0x").or_else(|| name.strip_prefix("0X")) {
            return u16::from_str_radix(hex, 16)
                .ok()
                .and_then(|id| self.msg(id));
        }
        let n = name
            .strip_prefix("MGMSG_")
            .or_else(|| name.strip_prefix("mgmsg_"))
            .unwrap_or(name);
        self.data
            .msgs
            .iter()
            .find(|m| m.name.eq_ignore_ascii_case(n))
    }

    /// A sub-message of a group.
    pub fn sub(&self, group: &str, id: u16) -> Option<&SubDef> {
        self.data
            .subs
            .iter()
            .find(|s| s.group == group && s.id == id)
    }

    /// A sub-message of `m`'s group (`g`) by id, through a per-message index (the decoder's path).
    #[inline]
    pub fn sub_of(&self, m: &MsgDef, g: &str, id: u16) -> Option<&SubDef> {
        match self.by_id[m.id as usize] {
            u16::MAX => self.sub(g, id),
            i => self.msg_subs[i as usize]
                .iter()
                .find(|(s, _)| *s == id)
                .map(|(_, x)| &self.data.subs[*x]),
        }
    }

    /// A sub-message of a group by name (case-insensitive).
    pub fn sub_by_name(&self, group: &str, name: &str) -> Option<&SubDef> {
        self.data
            .subs
            .iter()
            .find(|s| s.group == group && s.name.eq_ignore_ascii_case(name))
    }

    /// An enumeration by index (as in [`Field::enumeration`]).
    pub fn enum_def(&self, i: usize) -> &EnumDef {
        &self.data.enums[i]
    }

    /// A flag set by index (as in [`Field::flags`]).
    pub fn flags_def(&self, i: usize) -> &FlagsDef {
        &self.data.flags[i]
    }

    /// All enumerations.
    pub fn enums(&self) -> &[EnumDef] {
        &self.data.enums
    }

    /// All flag sets.
    pub fn flag_sets(&self) -> &[FlagsDef] {
        &self.data.flags
    }

    /// Whether `m` exists in this length (header-only when `!has_data`).
    /// The rule of each form is [`Form::accepts_len`]; a `sub` form takes the lengths of its
    /// group's sub-messages' forms.
    #[inline]
    pub fn accepts_len(&self, m: &MsgDef, has_data: bool, len: usize) -> bool {
        if let Some(set) = self.lens_of(m) {
            if !has_data {
                return set.hdr;
            }
            if let Some(word) = set.data.get(len / 64) {
                return word >> (len % 64) & 1 != 0;
            }
        }
        self.accepts_len_by_forms(m, has_data, len)
    }

    /// The precomputed lengths of `m`, when it is this table's message.
    #[inline]
    fn lens_of(&self, m: &MsgDef) -> Option<&LenSet> {
        let i = usize::from(*self.by_id.get(usize::from(m.id))?);
        let ours = self.data.msgs.get(i).is_some_and(|x| std::ptr::eq(x, m));
        self.lens.get(i).filter(|_| ours)
    }

    /// The lengths message `i` exists in up to 255 bytes: what
    /// [`accepts_len_by_forms`](Self::accepts_len_by_forms) says, its group's sub-messages found
    /// through `msg_subs` (the same group rule).
    fn len_set(&self, i: usize) -> LenSet {
        let m = &self.data.msgs[i];
        let mut set = LenSet {
            hdr: m.forms.iter().any(|f| f.kind == FormKind::Header),
            data: [0; 4],
        };
        let subs = self.msg_subs[i].iter().map(|&(_, s)| &self.data.subs[s]);
        let sub_forms = subs.flat_map(|s| s.forms.iter());
        let has_sub = m.forms.iter().any(|f| f.kind == FormKind::Sub);
        let forms = m.forms.iter().chain(sub_forms.filter(|_| has_sub));
        for f in forms {
            // One length each (the common case), else tried length by length.
            let lens = match f.kind {
                FormKind::Header | FormKind::Sub => 0..0,
                FormKind::Data(n) => usize::from(n)..usize::from(n) + 1,
                FormKind::Open(_) => 0..256,
            };
            for len in lens.filter(|&n| n < 256) {
                if f.accepts_len(true, len) {
                    set.data[len / 64] |= 1 << (len % 64);
                }
            }
        }
        set
    }

    /// [`accepts_len`](Self::accepts_len) from the forms themselves.
    fn accepts_len_by_forms(&self, m: &MsgDef, has_data: bool, len: usize) -> bool {
        m.forms.iter().any(|f| match f.kind {
            FormKind::Sub => {
                has_data
                    && self.data.subs.iter().any(|s| {
                        Some(s.group) == m.subs
                            && s.forms.iter().any(|sf| sf.accepts_len(true, len))
                    })
            }
            _ => f.accepts_len(has_data, len),
        })
    }

    /// The largest data packet the framer takes for `m`: the spec's 255 bytes, or its `maxlen=`.
    #[inline]
    pub fn max_data_len(&self, m: &MsgDef) -> usize {
        m.max_len.map_or(crate::apt::MAX_DATA_LEN, |x| {
            (x as usize).max(crate::apt::MAX_DATA_LEN)
        })
    }

    /// The ids of the messages that answer `m` (precomputed [`replies_of`](Self::replies_of)).
    #[inline]
    pub fn reply_ids(&self, m: &MsgDef) -> &[u16] {
        match self.by_id[m.id as usize] {
            u16::MAX => &[],
            i => self.reply_ids.get(i as usize).map_or(&[], |v| v.as_slice()),
        }
    }

    /// Whether any form of message `id` (or of its sub-messages) has a field called `name`:
    /// a filter on a field skips, without decoding, the frames that cannot have it.
    #[inline]
    pub fn may_have_field(&self, id: u16, name: &str) -> bool {
        match self.by_id[id as usize] {
            u16::MAX => false,
            i => self
                .field_names
                .get(i as usize)
                .is_some_and(|v| v.contains(&name)),
        }
    }

    /// How many kinds of message `m` answers (0 for one that answers none; saturates at 255).
    #[inline]
    pub fn requesters(&self, m: &MsgDef) -> u8 {
        match self.by_id[m.id as usize] {
            u16::MAX => 0,
            i => self.requesters.get(i as usize).copied().unwrap_or(0),
        }
    }

    /// The messages that answer `m`: its `reply=` list, or GET_x for REQ_x.
    pub fn replies_of<'a>(&'a self, m: &'a MsgDef) -> Vec<&'a MsgDef> {
        let mut out: Vec<&MsgDef> = m.reply.iter().filter_map(|r| self.msg_by_name(r)).collect();
        if out.is_empty() {
            if let Some((get, Access::Req)) = self.readback_of(m) {
                out.push(get);
            }
        }
        out
    }

    /// For a SET_x or REQ_x message, the GET_x that carries its values, and which of the two
    /// `m` is. The spec's naming rule (SET_x / REQ_x / GET_x), applied here only.
    pub fn readback_of(&self, m: &MsgDef) -> Option<(&MsgDef, Access)> {
        let (i, access) = match (m.name.find("_SET_"), m.name.find("_REQ_")) {
            (Some(i), _) => (i, Access::Set),
            (None, Some(i)) => (i, Access::Req),
            (None, None) => return None,
        };
        let get = format!("{}_GET_{}", &m.name[..i], &m.name[i + 5..]);
        Some((self.msg_by_name(&get)?, access))
    }
}

/// What a SET_x or REQ_x message does with the values of its GET_x ([`Table::readback_of`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// SET_x: sets them.
    Set,
    /// REQ_x: asks for them.
    Req,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_field(field: &'static str) -> Result<Table, TableErrors> {
        let text: &'static str = Box::leak(
            format!("msg 0x0413 MOT_SET_VELPARAMS h2d\n  form 4\n    {field}\n").into_boxed_str(),
        );
        Table::from_sources(&[("t.apt", text)])
    }

    /// A value's flags are the items whose mask's bits are all set, in the items' order,
    /// whether [`FlagsDef::set`] walks the items a value's bytes set (distinct one-bit masks:
    /// every set of the table here, some out of bit order) or tests every item (any other
    /// set).
    #[test]
    fn set_flags_are_the_items_whose_bits_are_all_set() {
        let slow = |d: &FlagsDef, x: u64| -> Vec<&'static str> {
            d.items
                .iter()
                .filter(|(m, _)| x & m == *m)
                .map(|(_, l)| *l)
                .collect()
        };
        let mut defs: Vec<FlagsDef> = Table::global().data.flags.clone();
        assert!(defs.iter().all(|d| d.set(0).walk));
        // Sets the walk may not take: a mask of two bits, of none, a bit twice, 65 items.
        let many: Vec<(u64, &'static str)> = (0..65).map(|i| (1 << (i % 64), "M")).collect();
        defs.push(FlagsDef::new("two", vec![(1, "A"), (6, "BC"), (8, "D")]));
        defs.push(FlagsDef::new("none", vec![(0, "ZERO"), (2, "B")]));
        defs.push(FlagsDef::new("same", vec![(4, "C"), (4, "C2")]));
        defs.push(FlagsDef::new("many", many));
        for d in &defs[defs.len() - 4..] {
            assert!(!d.set(0).walk, "{}", d.name);
        }
        // And sets it takes: bits out of order, the highest.
        defs.push(FlagsDef::new(
            "down",
            vec![(1 << 40, "C"), (4, "B"), (1, "A")],
        ));
        defs.push(FlagsDef::new("top", vec![(1, "LOW"), (1 << 63, "HIGH")]));
        for d in &defs[defs.len() - 2..] {
            assert!(d.set(0).walk, "{}", d.name);
        }
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut values = vec![0, u64::MAX, 1, 1 << 63, 6, 7, 0xFFFF_FFFF];
        for _ in 0..200 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            values.push(x);
            values.push(x & 0xFFFF);
        }
        for d in &defs {
            for &v in &values {
                assert_eq!(
                    d.set(v).map(|(_, l)| *l).collect::<Vec<_>>(),
                    slow(d, v),
                    "{} {v:#x}",
                    d.name
                );
            }
        }
    }

    /// The per-message length sets say what the forms say, for every message, both kinds of
    /// frame and every length up to beyond the largest; the
    /// data form that stops the decoder's walk of the forms is found at once; a message of
    /// another table is judged by its forms.
    #[test]
    fn length_sets_agree_with_the_forms() {
        let t = Table::global();
        for m in t.msgs() {
            let max = t.max_data_len(m) + 8;
            for has_data in [false, true] {
                for len in 0..=max {
                    assert_eq!(
                        t.accepts_len(m, has_data, len),
                        t.accepts_len_by_forms(m, has_data, len),
                        "{} has_data={has_data} len={len}",
                        m.name
                    );
                }
            }
            for len in 0..256 {
                // The form the walk of the forms stops at.
                let stop = m.forms.iter().position(|f| match f.kind {
                    FormKind::Sub => len >= 2,
                    FormKind::Header => false,
                    _ => f.accepts_len(true, len),
                });
                let want = match stop.map(|i| (i, m.forms[i].kind)) {
                    None => DataForm::NONE,
                    Some((_, FormKind::Sub)) => DataForm::WALK,
                    Some((i, _)) => DataForm(i as u8),
                };
                assert_eq!(m.data_form[len], want, "{} len={len}", m.name);
            }
        }
        // MOT_SET_VELPARAMS of a one-form table: 4 data bytes here, 14 in the global table.
        let other = one_field("i32 max_vel").expect("a table");
        let m = &other.msgs()[0];
        assert!(t.accepts_len(m, true, 4) && !t.accepts_len(m, true, 14));
        let m = t.msg(0x0413).expect("MOT_SET_VELPARAMS");
        assert!(!t.accepts_len(m, true, 4) && t.accepts_len(m, true, 14));
    }

    /// The pairer keeps a request's reply ids inline: no message may have more, and the
    /// per-form indexes name the fields they stand for.
    #[test]
    fn replies_fit_the_pairer_and_forms_are_indexed() {
        let t = Table::global();
        for m in t.msgs() {
            assert!(
                t.reply_ids(m).len() <= crate::pair::MAX_REPLIES,
                "{}",
                m.name
            );
        }
        let forms = t.msgs().iter().flat_map(|m| &m.forms);
        let forms = forms.chain(t.subs().iter().flat_map(|s| &s.forms));
        let mut chans = 0;
        for f in forms {
            let named = |n: &str| f.fields.iter().find(|x| x.name == n).map(|x| x.name);
            assert_eq!(f.chan_field().map(|x| x.name), named("chan_ident"));
            assert_eq!(f.sub_field().map(|x| x.name), named("sub_id"));
            let units = f.fields.iter().any(|x| x.q.is_some() || x.pct_of.is_some());
            assert!(!units || f.has_units());
            let maxima = f.fields.iter().any(|x| x.max_of.is_some());
            assert_eq!(f.has_maxima(), maxima);
            chans += usize::from(f.chan_field().is_some());
        }
        assert!(chans > 100, "{chans}");
        let t_ = t.msg_by_name("MOT_MOVE_ABSOLUTE").map(|m| m.id);
        let id = t_.unwrap_or(0);
        assert!(t.may_have_field(id, "absolute_position") && t.may_have_field(id, "chan_ident"));
        assert!(!t.may_have_field(id, "velocity") && !t.may_have_field(0xFFFF, "chan_ident"));
    }

    /// SET_x and REQ_x find their GET_x; other messages have none.
    #[test]
    fn readback_follows_the_naming_rule() {
        let t = Table::global();
        let m = |n: &str| t.msg_by_name(n).expect(n);
        let rb = |n: &str| t.readback_of(m(n)).map(|(g, a)| (g.name, a));
        assert_eq!(
            rb("MOT_SET_VELPARAMS"),
            Some(("MOT_GET_VELPARAMS", Access::Set))
        );
        assert_eq!(
            rb("MOT_REQ_VELPARAMS"),
            Some(("MOT_GET_VELPARAMS", Access::Req))
        );
        assert_eq!(rb("MOT_MOVE_HOME"), None);
        assert_eq!(rb("MOT_GET_VELPARAMS"), None);
    }

    /// `q=` marks a motion value and must come with the raw unit that names it honestly.
    #[test]
    fn motion_quantities_need_their_honest_raw_unit() {
        let t = one_field("i32 max_vel unit=vel_units q=vel").expect("valid");
        let f = &t.msgs()[0].forms[0].fields[0];
        assert_eq!((f.q, f.unit), (Some(Quantity::Vel), Some("vel_units")));
        let t = one_field("i32 vel1 unit=counts/s q=pos/s").expect("valid");
        assert_eq!(t.msgs()[0].forms[0].fields[0].q, Some(Quantity::PosPerSec));
        for (field, says) in [
            ("i32 acceleration unit=counts/s2", "acc_units q=acc"),
            ("i32 max_vel unit=counts/s", "needs its `q=`"),
            ("i32 max_vel unit=vel_units", "needs its `q=`"),
            (
                "i32 max_vel unit=counts/s q=vel",
                "`q=vel` needs `unit=vel_units`",
            ),
            ("i32 max_vel q=vel", "`q=vel` needs `unit=vel_units`"),
            ("i32 max_vel unit=vel_units q=speed", "bad `q=speed`"),
            (
                "i32 position unit=counts q=pos scale=2",
                "converts per stage",
            ),
            ("bytes[4] position unit=counts q=pos", "not one number"),
            ("i32[2] position unit=counts q=pos", "not one number"),
        ] {
            let e = one_field(field).expect_err(field).to_string();
            assert!(e.contains(says), "{field}: {e}");
        }
        // Positions without `q=` (encoder readbacks) stay plain counts.
        assert!(one_field("i32 encoder_count unit=counts").is_ok());
    }
}
