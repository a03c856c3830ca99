//! Windows USBPcap packets (link type 249).

use super::*;

pub(super) fn parse_usbpcap<'a>(
    data: &'a [u8],
    orig_len: u32,
    off: u64,
    out: &mut Vec<UsbOut>,
) -> Option<Urb<'a>> {
    if data.len() < USBPCAP_HDR {
        diag(
            out,
            off,
            "usb_record_too_short",
            format!(
                "USBPcap record of {} bytes{} is shorter than its {USBPCAP_HDR}-byte header",
                data.len(),
                snap_note(data.len(), orig_len)
            ),
        );
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
        diag(
            out,
            off,
            "usb_bad_header",
            format!("USBPcap header length {hlen} is less than {min}"),
        );
        return None;
    }
    if hlen > data.len() {
        diag(
            out,
            off,
            "usb_record_too_short",
            format!(
                "USBPcap record of {} bytes{} is shorter than its {hlen}-byte header",
                data.len(),
                snap_note(data.len(), orig_len)
            ),
        );
        return None;
    }
    let id = le64(data, 2);
    let submit = data[16] & 1 == 0;
    let bus = le16(data, 17);
    let addr = le16(data, 19);
    let ep = data[21];
    let data_len = le32(data, 23);
    match transfer {
        XFER_CONTROL | XFER_BULK => {}
        XFER_ISO | XFER_INTERRUPT | USBPCAP_IRP_INFO | USBPCAP_UNKNOWN => return None,
        other => {
            diag(
                out,
                off,
                "usb_unknown_transfer_type",
                format!("USBPcap transfer type 0x{other:02x} is none of 0-3, 0xfe, 0xff (usb {bus}:{addr})"),
            );
            return None;
        }
    }
    let avail = &data[hlen..];
    let (mut payload, truncated) = match usize::try_from(data_len) {
        Ok(n) if n <= avail.len() => (&avail[..n], None),
        _ => (
            avail,
            Some(format!(
                "USBPcap header announces {data_len} data bytes, the record holds {}{}",
                avail.len(),
                snap_note(data.len(), orig_len)
            )),
        ),
    };
    let mut setup = None;
    if transfer == XFER_CONTROL {
        match data[USBPCAP_HDR] {
            USBPCAP_STAGE_SETUP if submit => {
                if payload.len() < 8 {
                    diag(
                        out,
                        off,
                        "usb_bad_header",
                        format!(
                            "USBPcap control setup stage with {} bytes instead of 8",
                            payload.len()
                        ),
                    );
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
