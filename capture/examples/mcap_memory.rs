//! Peak memory of reading a large MCAP file: `mcap_memory [MESSAGES]` writes MESSAGES (default
//! 100,000) raw messages of 4 KiB each, uncompressed, to a temporary file, reads it back with
//! [`McapReader`] and prints the file's size, the chunks read and the process's peak resident
//! memory (VmHWM), which stays flat however large the file (the reader streams it).

use aptscope_capture::mcap::{McapReader, RAW_ENCODING};
use aptscope_capture::{Event, Reader};
use mcap::records::MessageHeader;
use std::collections::BTreeMap;
use std::io;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let messages: u32 = match std::env::args().nth(1) {
        Some(n) => n.parse()?,
        None => 100_000,
    };
    let path =
        std::env::temp_dir().join(format!("aptscope-mcap-large-{}.mcap", std::process::id()));
    {
        let f = io::BufWriter::new(std::fs::File::create(&path)?);
        let mut w = mcap::Writer::with_options(f, mcap::WriteOptions::new().compression(None))?;
        let mut m = BTreeMap::new();
        m.insert("stream".to_string(), "0".to_string());
        let ch = w.add_channel(0, "/serial/0/d2h", RAW_ENCODING, &m)?;
        let data: Vec<u8> = (0..4096u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
            .collect();
        for i in 0..messages {
            let h = MessageHeader {
                channel_id: ch,
                sequence: i,
                log_time: u64::from(i),
                publish_time: u64::from(i),
            };
            w.write_to_known_channel(&h, &data)?;
        }
        w.finish()?;
    }
    let size = std::fs::metadata(&path)?.len();
    let read = (|| -> io::Result<(u64, u64)> {
        let mut r = McapReader::open(&path)?;
        let (mut n, mut bytes) = (0u64, 0u64);
        while let Some(e) = r.next_event() {
            if let Event::Chunk(c) = e {
                n += 1;
                bytes += c.bytes.len() as u64;
            }
        }
        Ok((n, bytes))
    })();
    let _ = std::fs::remove_file(&path);
    let (n, bytes) = read?;
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let hwm = status
        .lines()
        .find(|l| l.starts_with("VmHWM"))
        .unwrap_or("VmHWM: ?");
    println!("file {size} bytes, {n} of {messages} messages read, {bytes} bytes; {hwm}");
    Ok(())
}
