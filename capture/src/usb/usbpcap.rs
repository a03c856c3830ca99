//! Windows USBPcap packets (link type 249).

use super::*;

pub(super) fn parse_usbpcap<'a>(
    data: &'a [u8],
    orig_len: u32,
    off: u64,
    out: &mut Vec<UsbOut>,
) -> Option<Urb<'a>> {
    if !holds_header(UsbFormat::UsbPcap, USBPCAP_HDR, data, orig_len, off, out) {
        return None;
    }
    let hlen = usize::from(le16(data, 0));
    let transfer = data[22];
    let min = if transfer == XFER_CONTROL {
        USBPCAP_HDR + 1
    } else {
        USBPCAP_HDR
    };
    if hlen < min {
        usb_diag(out, off, UsbProblem::HeaderTooShort { min, found: hlen });
        return None;
    }
    if !holds_header(UsbFormat::UsbPcap, hlen, data, orig_len, off, out) {
        return None;
    }
    let id = le64(data, 2);
    let submit = data[16] & 1 == 0;
    let bus = le16(data, 17);
    let addr = le16(data, 19);
    let ep = data[21];
    let data_len = le32(data, 23);
    let ignored = [USBPCAP_IRP_INFO, USBPCAP_UNKNOWN];
    if !shown_transfer(
        UsbFormat::UsbPcap,
        transfer,
        &ignored,
        (bus, addr),
        off,
        out,
    ) {
        return None;
    }
    let avail = &data[hlen..];
    let (mut payload, truncated) = match usize::try_from(data_len) {
        Ok(n) if n <= avail.len() => (&avail[..n], None),
        _ => (
            avail,
            Some(UrbCut::Record {
                format: UsbFormat::UsbPcap,
                expected: u64::from(data_len),
                found: avail.len(),
                record: data.len(),
                original: orig_len,
            }),
        ),
    };
    let mut setup = None;
    if transfer == XFER_CONTROL {
        match data[USBPCAP_HDR] {
            USBPCAP_STAGE_SETUP if submit => {
                if payload.len() < 8 {
                    let found = payload.len();
                    usb_diag(out, off, UsbProblem::ShortSetup { found });
                    return None;
                }
                let mut s = [0u8; 8];
                s.copy_from_slice(&payload[..8]);
                setup = Some(s);
                payload = &payload[8..];
            }
            USBPCAP_STAGE_STATUS => payload = &[],
            _ => {}
        }
    }
    Some(Urb {
        bus,
        addr,
        ep,
        xfer: transfer,
        submit,
        id,
        setup,
        data: payload,
        truncated,
    })
}
