//! `aptscope extcap`: aptscope as a Wireshark capture source (Wireshark's extcap interface, see
//! `man 4 extcap`). Wireshark runs every executable in its extcap folders with
//! `--extcap-interfaces`; a symlink there named `aptscope-extcap` (anything with `extcap` in
//! its name) makes the binary answer as if called `aptscope extcap …`. The capture is the tap:
//! a pseudo-terminal for the host program in front of the real port, written as pcapng into
//! the FIFO Wireshark reads, flushed packet by packet.

use aptscope_capture::live::serial::Flow;
use aptscope_capture::live::tap::{tap_main, TapOptions};
use aptscope_dissector::detect::Proto;
use std::ffi::OsStr;
use std::io::{self, Write};
use std::path::Path;

/// The generic interface: the serial port comes from its options.
const GENERIC: &str = "aptscope";
/// Per-port interfaces are `aptscope-ttyUSB0` for `/dev/ttyUSB0`.
const PORT_PREFIX: &str = "aptscope-";
/// The host-side link when the options give none (per-port interfaces add the port's name, so
/// that captures on two ports at once do not take each other's link).
const DEFAULT_LINK: &str = "/tmp/ttyAPT";
/// LINKTYPE_USER0, what the tap's pcapng uses (with direction flags).
const DLT_USER0: u32 = 147;
/// Baud rates offered in Wireshark's options dialog (any number is accepted).
const BAUDS: [u32; 8] = [
    9600, 19_200, 38_400, 57_600, 115_200, 230_400, 460_800, 921_600,
];

/// The arguments Wireshark passes to an extcap, and the tap's options as its dialog sets them.
#[derive(clap::Args)]
pub struct ExtcapArgs {
    /// List the interfaces (one generic, one per USB serial port present) and the version.
    #[arg(long)]
    extcap_interfaces: bool,
    /// Wireshark's version (given with --extcap-interfaces; not needed).
    #[arg(long, value_name = "VERSION", num_args = 0..=1, default_missing_value = "")]
    extcap_version: Option<String>,
    /// The interface the other requests are about.
    #[arg(long, value_name = "IFACE")]
    extcap_interface: Option<String>,
    /// List the interface's link types.
    #[arg(long)]
    extcap_dlts: bool,
    /// List the interface's options (Wireshark's dialog; tshark: `-o extcap.IFACE.OPTION:VALUE`).
    #[arg(long)]
    extcap_config: bool,
    /// Capture: run the tap and write pcapng into --fifo until Wireshark stops it.
    #[arg(long)]
    capture: bool,
    /// The FIFO Wireshark reads the capture from.
    #[arg(long, value_name = "PATH")]
    fifo: Option<String>,
    /// A capture filter: aptscope has none (use a display filter such as `apt.name`); an empty
    /// one is accepted.
    #[arg(long, value_name = "FILTER")]
    extcap_capture_filter: Option<String>,
    /// Control pipe from Wireshark (aptscope declares no controls; accepted and unused).
    #[arg(long, value_name = "PATH")]
    extcap_control_in: Option<String>,
    /// Control pipe to Wireshark (accepted and unused).
    #[arg(long, value_name = "PATH")]
    extcap_control_out: Option<String>,
    /// Option reload request (aptscope's options have nothing to reload; accepted).
    #[arg(long, value_name = "OPTION")]
    extcap_reload_option: Option<String>,
    /// The real serial port (default: the interface's, `aptscope-ttyUSB0` → /dev/ttyUSB0).
    #[arg(long)]
    device: Option<String>,
    /// Symlink the host program opens instead of the real port (default /tmp/ttyAPT).
    #[arg(long)]
    link: Option<String>,
    /// Protocol: apt (default) or elliptec.
    #[arg(long)]
    proto: Option<String>,
    /// Baud rate, or `auto` for the protocol's (APT 115200, Elliptec 9600).
    #[arg(long)]
    baud: Option<String>,
    /// Flow control: auto (the protocol's), none, rtscts, xonxoff.
    #[arg(long)]
    flow: Option<String>,
    /// Wait for a vanished device to come back instead of ending the capture.
    #[arg(long)]
    reconnect: bool,
}

/// Whether the program was called under a name meaning "be an extcap" (`aptscope-extcap`, a
/// symlink in Wireshark's extcap folder).
pub fn invoked_as_extcap(argv0: &OsStr) -> bool {
    Path::new(argv0)
        .file_name()
        .and_then(OsStr::to_str)
        .is_some_and(|n| n.contains("extcap"))
}

/// Answer Wireshark's request.
pub fn extcap_main(a: ExtcapArgs) -> io::Result<()> {
    let mut out = io::stdout().lock();
    if a.extcap_interfaces {
        out.write_all(interfaces(&serial_ports()).as_bytes())?;
        return out.flush();
    }
    let nothing_else = a.extcap_interface.is_none() && !a.capture && !a.extcap_config;
    if a.extcap_version.is_some() && nothing_else && !a.extcap_dlts {
        // Older Wireshark asks the version alone: the first line of the interfaces.
        out.write_all(
            interfaces(&[])
                .lines()
                .next()
                .unwrap_or_default()
                .as_bytes(),
        )?;
        out.write_all(b"\n")?;
        return out.flush();
    }
    let iface = a.extcap_interface.as_deref();
    let need_iface = || {
        iface.filter(|i| known(i)).ok_or_else(|| match iface {
            Some(i) => bad(format!(
                "unknown interface {i} (aptscope's are `{GENERIC}` and `{PORT_PREFIX}PORT`)"
            )),
            None => bad("--extcap-interface is needed".into()),
        })
    };
    if a.extcap_dlts {
        need_iface()?;
        out.write_all(dlts().as_bytes())?;
        return out.flush();
    }
    if a.extcap_config {
        out.write_all(config(need_iface()?).as_bytes())?;
        return out.flush();
    }
    if let Some(f) = a
        .extcap_capture_filter
        .as_deref()
        .filter(|f| !f.trim().is_empty())
    {
        return Err(bad(format!(
            "capture filter `{f}`: aptscope has no capture filters; capture everything and use \
             a display filter (`apt.name == \"MOT_MOVE_HOMED\"`, `ell.cmd`)"
        )));
    }
    if a.capture {
        return capture(need_iface()?, &a);
    }
    if a.extcap_capture_filter.is_some() {
        // Wireshark checking a (here empty) capture filter: valid.
        return Ok(());
    }
    Err(bad(
        "aptscope extcap: give --extcap-interfaces, --extcap-dlts, --extcap-config or --capture \
         (Wireshark does; see `aptscope extcap --help` and docs/wireshark.md)"
            .into(),
    ))
}

fn bad(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

/// USB serial ports present (`/dev/ttyUSB*`, `/dev/ttyACM*`), sorted.
fn serial_ports() -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir("/dev")
        .map(|d| {
            d.filter_map(|e| e.ok()?.file_name().into_string().ok())
                .filter(|n| n.starts_with("ttyUSB") || n.starts_with("ttyACM"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Whether `iface` is one of ours (a per-port one need not be present any more: its port may
/// come back, and `--device` may say another).
fn known(iface: &str) -> bool {
    iface == GENERIC || port_of(iface).is_some()
}

/// The port of a per-port interface.
fn port_of(iface: &str) -> Option<String> {
    let p = iface.strip_prefix(PORT_PREFIX)?;
    (!p.is_empty() && !p.contains(['/', '{', '}'])).then(|| format!("/dev/{p}"))
}

/// The host-side link of an interface: `/tmp/ttyAPT`, `/tmp/ttyAPT-ttyUSB0`.
fn default_link(iface: &str) -> String {
    match iface
        .strip_prefix(PORT_PREFIX)
        .filter(|_| port_of(iface).is_some())
    {
        Some(p) => format!("{DEFAULT_LINK}-{p}"),
        None => DEFAULT_LINK.into(),
    }
}

/// `--extcap-interfaces`: the version, the generic interface and one per port.
fn interfaces(ports: &[String]) -> String {
    let mut s = format!(
        "extcap {{version={}}}{{display=aptscope: Thorlabs APT and Elliptec serial tap}}\n",
        env!("CARGO_PKG_VERSION")
    );
    s += &format!(
        "interface {{value={GENERIC}}}{{display=Thorlabs APT and Elliptec serial tap (port set in the options)}}\n"
    );
    for p in ports {
        s += &format!("interface {{value={PORT_PREFIX}{p}}}{{display=Thorlabs APT and Elliptec tap on /dev/{p}}}\n");
    }
    s
}

/// `--extcap-dlts`: the tap's pcapng link type.
fn dlts() -> String {
    format!("dlt {{number={DLT_USER0}}}{{name=USER0}}{{display=aptscope serial (APT, Elliptec)}}\n")
}

/// `--extcap-config`: the options dialog, the port defaulting to the interface's.
fn config(iface: &str) -> String {
    let device = port_of(iface).unwrap_or_else(|| "/dev/ttyUSB0".into());
    let link = default_link(iface);
    let mut s = String::new();
    let mut arg = |line: String| {
        s += &line;
        s.push('\n');
    };
    arg(format!(
        "arg {{number=0}}{{call=--device}}{{display=Serial port}}{{type=string}}\
         {{default={device}}}{{required=true}}{{tooltip=The controller's real serial port}}"
    ));
    arg(format!(
        "arg {{number=1}}{{call=--link}}{{display=Host-side link}}{{type=string}}\
         {{default={link}}}{{required=true}}{{tooltip=The host program opens this \
         symlink (a pseudo-terminal) instead of the real port}}"
    ));
    arg(
        "arg {number=2}{call=--proto}{display=Protocol}{type=selector}\
         {tooltip=Sets the line's default settings}"
            .into(),
    );
    arg("value {arg=2}{value=apt}{display=Thorlabs APT}{default=true}".into());
    arg("value {arg=2}{value=elliptec}{display=Elliptec}{default=false}".into());
    arg("arg {number=3}{call=--baud}{display=Baud rate}{type=selector}".into());
    arg(
        "value {arg=3}{value=auto}{display=The protocol's (APT 115200, Elliptec 9600)}\
         {default=true}"
            .into(),
    );
    for b in BAUDS {
        arg(format!(
            "value {{arg=3}}{{value={b}}}{{display={b}}}{{default=false}}"
        ));
    }
    arg("arg {number=4}{call=--flow}{display=Flow control}{type=selector}".into());
    for (v, d, def) in [
        ("auto", "The protocol's (APT RTS/CTS, Elliptec none)", true),
        ("none", "None", false),
        ("rtscts", "RTS/CTS", false),
        ("xonxoff", "XON/XOFF", false),
    ] {
        arg(format!(
            "value {{arg=4}}{{value={v}}}{{display={d}}}{{default={def}}}"
        ));
    }
    arg(
        "arg {number=5}{call=--reconnect}{display=Wait for the device to come back}\
         {type=boolflag}{default=false}{tooltip=Keep capturing when the port disappears}"
            .into(),
    );
    s
}

/// `--capture`: the tap, writing into the FIFO until Wireshark stops it (SIGTERM) or closes
/// the FIFO.
/// The tap failed before opening the FIFO (no such device …): Wireshark's dumpcap may be
/// blocked opening it for reading, waiting for a writer that never comes. Open it and close it
/// so dumpcap sees the end at once (the error itself goes to standard error, which Wireshark
/// shows); give up after a few seconds if nobody is reading.
fn release_reader(fifo: &str) {
    use std::os::unix::fs::OpenOptionsExt;
    const O_NONBLOCK: i32 = 0o4000;
    const ENXIO: i32 = 6;
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
    loop {
        let r = std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(O_NONBLOCK)
            .open(fifo);
        match r {
            // No reader yet (ENXIO): dumpcap opens the FIFO after starting us.
            Err(e) if e.raw_os_error() == Some(ENXIO) && std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            _ => return,
        }
    }
}

fn capture(iface: &str, a: &ExtcapArgs) -> io::Result<()> {
    let fifo = a
        .fifo
        .clone()
        .ok_or_else(|| bad("--capture needs --fifo".into()))?;
    let device = a
        .device
        .clone()
        .filter(|d| !d.is_empty())
        .or_else(|| port_of(iface))
        .ok_or_else(|| bad("no serial port: set the interface's Serial port option".into()))?;
    let proto = match a.proto.as_deref().unwrap_or("apt") {
        "apt" | "" => Proto::Apt,
        "elliptec" | "ell" => Proto::Elliptec,
        p => return Err(bad(format!("unknown protocol {p} (apt, elliptec)"))),
    };
    let baud = match a.baud.as_deref().unwrap_or("auto") {
        "auto" | "" => None,
        b => Some(
            b.parse::<u32>()
                .ok()
                .filter(|&b| b > 0)
                .ok_or_else(|| bad(format!("bad baud rate {b}")))?,
        ),
    };
    let flow = match a.flow.as_deref().unwrap_or("auto") {
        "auto" | "" => None,
        f => Some(
            Flow::parse(f)
                .ok_or_else(|| bad(format!("unknown flow control {f} (none, rtscts, xonxoff)")))?,
        ),
    };
    let link = a
        .link
        .clone()
        .filter(|l| !l.is_empty())
        .unwrap_or_else(|| default_link(iface));
    let mut o = TapOptions::new(device, Some(link));
    o.live.proto = proto;
    o.live.baud = baud;
    o.live.flow = flow;
    o.live.write = Some(fifo.clone());
    o.stream = true;
    o.live.quiet = true;
    o.live.reconnect = a.reconnect;
    o.live.signals = true;
    // Wireshark shows anything on standard error as an error: only a failure is said there.
    o.live.say = aptscope_capture::Say::Nothing;
    let stats = tap_main(o);
    let stats = match stats {
        Ok(s) => s,
        Err(e) => {
            // Said before the FIFO is released: dumpcap shows what the extcap wrote to
            // standard error by the time the FIFO ends.
            aptscope_capture::note!("aptscope: {e}");
            let _ = io::stderr().flush();
            release_reader(&fifo);
            std::process::exit(1);
        }
    };
    if let Some(d) = stats.disconnects.last().filter(|_| !a.reconnect) {
        // The capture ended because of it: say why (Wireshark shows it).
        return Err(io::Error::other(format!("{} gone: {}", d.port, d.error)));
    }
    // Wireshark closing the FIFO is how a capture normally ends.
    if stats.file_matches() || stats.reader_closed {
        Ok(())
    } else {
        Err(io::Error::other(
            "the capture does not hold every forwarded byte (see the counts above)",
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn port_interfaces_map_to_their_device_and_nothing_else() {
        assert_eq!(port_of("aptscope-ttyUSB0").as_deref(), Some("/dev/ttyUSB0"));
        assert_eq!(port_of("aptscope"), None);
        assert_eq!(port_of("aptscope-"), None);
        assert_eq!(port_of("aptscope-../x/y"), None);
        assert!(known("aptscope") && !known("eth0"));
        assert!(invoked_as_extcap(OsStr::new(
            "/home/u/.config/wireshark/extcap/aptscope-extcap"
        )));
        assert!(!invoked_as_extcap(OsStr::new("/usr/bin/aptscope")));
    }

    #[test]
    fn every_line_is_one_extcap_sentence() {
        let text = [
            interfaces(&["ttyUSB0".into(), "ttyACM1".into()]),
            dlts(),
            config("aptscope-ttyUSB0"),
        ]
        .concat();
        for l in text.lines() {
            let (kw, rest) = l.split_once(' ').unwrap_or_default();
            assert!(
                ["extcap", "interface", "dlt", "arg", "value"].contains(&kw),
                "{l}"
            );
            assert!(rest.starts_with('{') && rest.ends_with('}'), "{l}");
            // Balanced and never nested: the values carry no braces.
            let inner = &rest[1..rest.len() - 1];
            for part in inner.split("}{") {
                assert!(part.contains('=') && !part.contains(['{', '}']), "{l}");
            }
        }
        assert!(text.contains(
            "interface {value=aptscope-ttyACM1}{display=Thorlabs APT and Elliptec tap on /dev/ttyACM1}"
        ));
        assert!(config("aptscope-ttyUSB0").contains("{default=/dev/ttyUSB0}"));
        assert!(config("aptscope-ttyUSB0").contains("{default=/tmp/ttyAPT-ttyUSB0}"));
        assert!(config("aptscope").contains("{default=/tmp/ttyAPT}"));
    }
}
