//! A checked view over the 6-byte APT header, and the address space.

/// Length of every APT header.
pub const HEADER_LEN: usize = 6;

/// Largest data packet the framer accepts. The spec: "currently no datapacket exceeds 255
/// bytes in length"; anything longer is treated as a corrupt header, not a frame.
pub const MAX_DATA_LEN: usize = 255;

/// Bit 7 of the destination byte: a data packet follows the header.
pub const DATA_FLAG: u8 = 0x80;

/// A source or destination address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Addr {
    /// 0x01: the host (control PC).
    Host,
    /// 0x11: rack controller, motherboard of a card-slot system, comms router.
    Rack,
    /// 0x21–0x2A: bay 0–9 of a card-slot system.
    Bay(u8),
    /// 0x50: generic USB hardware unit.
    Usb,
    /// Any other value.
    Unknown(u8),
}

impl Addr {
    /// Classify an address byte (without the 0x80 data flag).
    #[inline]
    pub fn from_byte(b: u8) -> Addr {
        match b {
            0x01 => Addr::Host,
            0x11 => Addr::Rack,
            0x21..=0x2A => Addr::Bay(b - 0x21),
            0x50 => Addr::Usb,
            x => Addr::Unknown(x),
        }
    }

    /// The address byte.
    pub fn byte(self) -> u8 {
        match self {
            Addr::Host => 0x01,
            Addr::Rack => 0x11,
            Addr::Bay(n) => 0x21 + n,
            Addr::Usb => 0x50,
            Addr::Unknown(x) => x,
        }
    }

    /// Whether the spec defines this address.
    #[inline]
    pub fn is_known(self) -> bool {
        !matches!(self, Addr::Unknown(_))
    }

    /// Bay index for bay addresses.
    pub fn bay(self) -> Option<u8> {
        match self {
            Addr::Bay(n) => Some(n),
            _ => None,
        }
    }

    /// Short name: `host`, `rack`, `bay0`…`bay9`, `usb`, or `0xNN` for an unknown address.
    pub fn name(self) -> AddrName {
        AddrName(self)
    }

    /// Parse a name as written by users: `host`, `rack`, `usb`, `bay3`, `0x22`, `34`.
    pub fn parse(s: &str) -> Option<Addr> {
        let s = s.trim().to_ascii_lowercase();
        Some(match s.as_str() {
            "host" | "pc" => Addr::Host,
            "rack" | "motherboard" | "mb" => Addr::Rack,
            "usb" | "generic" | "device" => Addr::Usb,
            _ => {
                if let Some(n) = s.strip_prefix("bay") {
                    let n: u8 = n.parse().ok()?;
                    if n > 9 {
                        return None;
                    }
                    Addr::Bay(n)
                } else if let Some(h) = s.strip_prefix("0x") {
                    Addr::from_byte(u8::from_str_radix(h, 16).ok()? & 0x7F)
                } else {
                    Addr::from_byte(s.parse::<u8>().ok()? & 0x7F)
                }
            }
        })
    }
}

/// Display helper for [`Addr::name`] (no allocation).
#[derive(Debug, Clone, Copy)]
pub struct AddrName(Addr);

impl std::fmt::Display for AddrName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Addr::Host => f.pad("host"),
            Addr::Rack => f.pad("rack"),
            Addr::Usb => f.pad("usb"),
            Addr::Bay(n) => f.pad(&format!("bay{n}")),
            Addr::Unknown(x) => f.pad(&format!("0x{x:02X}")),
        }
    }
}

/// Lookup of known address bytes, for the framer's hot path.
pub(crate) static KNOWN_ADDR: [bool; 256] = {
    let mut t = [false; 256];
    t[0x01] = true;
    t[0x11] = true;
    let mut b = 0x21;
    while b <= 0x2A {
        t[b] = true;
        b += 1;
    }
    t[0x50] = true;
    t
};

/// A view over the first 6 bytes of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header<'a>(&'a [u8; HEADER_LEN]);

impl<'a> Header<'a> {
    /// View the first 6 bytes of `b`; `None` when it is shorter.
    #[inline]
    pub fn new(b: &'a [u8]) -> Option<Header<'a>> {
        b.get(..HEADER_LEN)
            .and_then(|h| h.try_into().ok())
            .map(Header)
    }
    /// The message id (bytes 0–1, little endian).
    #[inline]
    pub fn msg_id(&self) -> u16 {
        u16::from_le_bytes([self.0[0], self.0[1]])
    }
    /// Whether the 0x80 "data packet follows" bit of the destination byte is set.
    #[inline]
    pub fn has_data(&self) -> bool {
        self.0[4] & DATA_FLAG != 0
    }
    /// param1 (byte 2): meaningful for header-only messages.
    #[inline]
    pub fn param1(&self) -> u8 {
        self.0[2]
    }
    /// param2 (byte 3): meaningful for header-only messages.
    #[inline]
    pub fn param2(&self) -> u8 {
        self.0[3]
    }
    /// Data packet length (bytes 2–3) when [`has_data`](Self::has_data), else 0.
    #[inline]
    pub fn data_len(&self) -> usize {
        if self.has_data() {
            u16::from_le_bytes([self.0[2], self.0[3]]) as usize
        } else {
            0
        }
    }
    /// The destination byte without the data flag.
    #[inline]
    pub fn dst_byte(&self) -> u8 {
        self.0[4] & !DATA_FLAG
    }
    /// The source byte.
    #[inline]
    pub fn src_byte(&self) -> u8 {
        self.0[5]
    }
    /// The destination address.
    #[inline]
    pub fn dst(&self) -> Addr {
        Addr::from_byte(self.dst_byte())
    }
    /// The source address.
    #[inline]
    pub fn src(&self) -> Addr {
        Addr::from_byte(self.src_byte())
    }
}

/// Build a header.
pub fn emit_header(
    id: u16,
    p1_or_len: [u8; 2],
    has_data: bool,
    dst: u8,
    src: u8,
) -> [u8; HEADER_LEN] {
    let idb = id.to_le_bytes();
    let d = if has_data {
        dst | DATA_FLAG
    } else {
        dst & !DATA_FLAG
    };
    [idb[0], idb[1], p1_or_len[0], p1_or_len[1], d, src]
}
