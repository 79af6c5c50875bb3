//! The boards' defmt logs, decoded here (no `defmt-print` needed): QEMU's standard output
//! carries the frames defmt-semihosting writes; the ELF's `.defmt` table turns them into text.
//! A line is the message itself for `info`, and `ERROR: …` / `WARN: …` etc. for the others.

use crate::util::Result;
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
        Ok(Self::from_table(table))
    }

    /// The decoder for an image's `table`.
    fn from_table(table: Table) -> Self {
        let table: &'static Table = Box::leak(Box::new(table));
        Self {
            stream: table.new_stream_decoder(),
            recoverable: table.encoding().can_recover(),
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A table of three messages (info with a u8, error with a hex u32, warn), in `encoding`
    /// ("Raw" or "Rzcobs"), as `Table`'s serde form has it.
    fn table(encoding: &str) -> Table {
        let entry = |tag: &str, string: &str| serde_json::json!({"string": {"tag": tag, "string": string}, "raw_symbol": "x"});
        serde_json::from_value(serde_json::json!({
            "timestamp": null,
            "entries": {
                "0": entry("Info", "t_s={=u8} mode=profile"),
                "1": entry("Error", "HardFault at pc={=u32:#010x}"),
                "2": entry("Warn", "lost {=u16} bytes"),
            },
            "bitflags": {},
            "encoding": encoding,
        }))
        .unwrap()
    }

    #[test]
    fn lines_and_levels() {
        let mut d = LogDecoder::from_table(table("Raw"));
        assert!(!d.recoverable);
        // Raw frames: the index (u16, little-endian), then the arguments.
        let frames = [0, 0, 7, 1, 0, 0x34, 0x12, 0, 8, 2, 0, 3, 0];
        assert_eq!(
            d.feed(&frames).unwrap(),
            [
                "t_s=7 mode=profile",
                "ERROR: HardFault at pc=0x08001234",
                "WARN: lost 3 bytes"
            ]
        );
        // A frame cut in two: its line when it is whole.
        assert_eq!(d.feed(&[0, 0]).unwrap(), Vec::<String>::new());
        assert_eq!(d.feed(&[42]).unwrap(), ["t_s=42 mode=profile"]);
        // An index the table does not have: without recovery, an error.
        assert!(d.feed(&[9, 0]).is_err());
    }

    #[test]
    fn images() {
        let missing = Path::new("/nonexistent/pump-qemu");
        assert!(LogDecoder::new(missing).is_err());
        assert!(decode(missing, &[]).is_err());
        // A file that is no ELF.
        let e = LogDecoder::new(&crate::util::root().join("Cargo.toml"))
            .err()
            .unwrap();
        assert!(e.contains("defmt table"), "{e}");
    }
}
