//! Raw byte streams and hex text, from a file or standard input, read in bounded chunks.

use aptscope_dissector::diag::Diag;
use aptscope_dissector::hex::HexDecoder;
use std::fs::File;
use std::io::{self, Read};

/// How the input encodes the byte stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputFormat {
    /// The bytes themselves.
    Raw,
    /// Hex text, any whitespace (`xxd -p`, spec-style `53, 04, …`).
    Hex,
}

/// Size of each read.
pub const CHUNK: usize = 64 * 1024;

/// A byte stream read in chunks from a file or stdin.
pub struct ByteSource {
    reader: Box<dyn Read>,
    format: InputFormat,
    hex: HexDecoder,
    buf: Vec<u8>,
    out: Vec<u8>,
    diags: Vec<Diag>,
    done: bool,
}

impl ByteSource {
    /// Open `path` (`-` for standard input).
    pub fn open(path: &str, format: InputFormat) -> io::Result<Self> {
        let reader: Box<dyn Read> = if path == "-" {
            Box::new(io::stdin())
        } else {
            Box::new(File::open(path)?)
        };
        Ok(Self::from_reader(reader, format))
    }

    /// Read from any reader.
    pub fn from_reader(reader: Box<dyn Read>, format: InputFormat) -> Self {
        ByteSource {
            reader,
            format,
            hex: HexDecoder::new(),
            buf: vec![0; CHUNK],
            out: Vec::with_capacity(CHUNK),
            diags: vec![],
            done: false,
        }
    }

    /// The next chunk of stream bytes, with any input diagnostics found while producing it
    /// (hex text problems, with text offsets). `None` at the end of input.
    pub fn next_chunk(&mut self) -> io::Result<Option<(&[u8], &[Diag])>> {
        if self.done {
            return Ok(None);
        }
        self.diags.clear();
        self.out.clear();
        loop {
            let n = match self.reader.read(&mut self.buf) {
                Ok(n) => n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if n == 0 {
                self.done = true;
                if self.format == InputFormat::Hex {
                    self.hex.finish(&mut self.diags);
                }
                if self.diags.is_empty() {
                    return Ok(None);
                }
                return Ok(Some((&self.out, &self.diags)));
            }
            match self.format {
                InputFormat::Raw => return Ok(Some((&self.buf[..n], &self.diags))),
                InputFormat::Hex => {
                    self.hex
                        .push(&self.buf[..n], &mut self.out, &mut self.diags);
                    if !self.out.is_empty() || !self.diags.is_empty() {
                        return Ok(Some((&self.out, &self.diags)));
                    }
                }
            }
        }
    }
}
