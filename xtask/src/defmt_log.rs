//! The boards' defmt logs, decoded here (no `defmt-print` needed): QEMU's standard output
//! carries the frames defmt-semihosting writes; the ELF's `.defmt` table turns them into text.
//! A line is the message itself for `info`, and `ERROR: …` / `WARN: …` etc. for the others.

use super::Result;
use defmt_decoder::{DecodeError, StreamDecoder, Table};
use std::path::Path;

/// A stream decoder for one image's frames.
pub struct LogDecoder {
    // The stream decoder borrows the table: both live as long as the decoder (leaked once
    // per image decoded, a few KB).
    stream: Box<dyn StreamDecoder + Send + 'static>,
    recoverable: bool,
}

impl LogDecoder {
    /// The decoder for the image at `elf`.
    pub fn new(elf: &Path) -> Result<Self> {
        let bytes = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
        let table = Table::parse(&bytes)
            .map_err(|e| format!("{}: defmt table: {e}", elf.display()))?
            .ok_or_else(|| format!("{}: no defmt table", elf.display()))?;
        let table: &'static Table = Box::leak(Box::new(table));
        Ok(Self {
            stream: table.new_stream_decoder(),
            recoverable: table.encoding().can_recover(),
        })
    }

    /// Takes `bytes` from the stream; returns the lines they complete.
    pub fn feed(&mut self, bytes: &[u8]) -> Result<Vec<String>> {
        self.stream.received(bytes);
        let mut lines = vec![];
        loop {
            match self.stream.decode() {
                Ok(frame) => {
                    let msg = frame.display_message().to_string();
                    lines.push(match frame.level().map(|l| l.as_str()) {
                        None | Some("info") => msg,
                        Some(level) => format!("{}: {msg}", level.to_uppercase()),
                    });
                }
                Err(DecodeError::UnexpectedEof) => return Ok(lines),
                Err(DecodeError::Malformed) if self.recoverable => {
                    lines.push("WARN: (a malformed defmt frame was skipped)".into())
                }
                Err(DecodeError::Malformed) => return Err("malformed defmt frame".into()),
            }
        }
    }
}

/// The whole log of an image's run.
pub fn decode(elf: &Path, bytes: &[u8]) -> Result<String> {
    let mut d = LogDecoder::new(elf)?;
    Ok(d.feed(bytes)?.join("\n") + "\n")
}
