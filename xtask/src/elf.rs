//! What an ELF image weighs (the `object` crate): its bytes by kind, its largest symbols, and
//! the software-f64 routines it holds.

use crate::util::Result;
use object::{Object, ObjectSection, ObjectSymbol, SectionFlags, SymbolKind};
use serde::Serialize;
use std::collections::HashSet;
use std::path::Path;

/// Bytes of an image by kind, from its ELF sections.
#[derive(Debug, Default, Clone, Copy, Serialize)]
pub struct Size {
    /// text + rodata + data: what is programmed into flash.
    pub flash: u64,
    /// data + bss: static RAM.
    pub ram: u64,
    /// Executable sections.
    pub text: u64,
    /// Read-only data (and the vector table).
    pub rodata: u64,
    /// Initialised data (in flash and in RAM).
    pub data: u64,
    /// Zeroed and uninitialised data (`.bss`, `.uninit`).
    pub bss: u64,
}

/// One symbol of an image.
#[derive(Debug, Clone, Serialize)]
pub struct Symbol {
    /// Size, bytes.
    pub bytes: u64,
    /// Demangled name.
    pub name: String,
}

/// `true` for a compiler-builtins routine of software double precision: the ARM EABI names
/// (`__aeabi_dadd`, `__aeabi_dcmpeq`, `__aeabi_d2f`, `__aeabi_f2d`, `__aeabi_i2d`, …) and the
/// GCC ones (`__adddf3`, `__eqdf2`, `__extendsfdf2`, `__truncdfsf2`, `__fixdfsi`,
/// `__floatsidf`, `__powidf2`, …).
pub fn is_soft_f64(name: &str) -> bool {
    if let Some(rest) = name.strip_prefix("__aeabi_") {
        return (rest.starts_with('d') && !rest.starts_with("div")) || rest.ends_with("2d");
    }
    name.strip_prefix("__").is_some_and(|rest| {
        rest.contains("df")
            && rest
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit())
    })
}

/// Sizes, largest symbols and software-f64 routines of the ELF at `path`.
pub fn read_elf(path: &Path, largest: usize) -> Result<(Size, Vec<Symbol>, Vec<String>)> {
    let what = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let bytes = std::fs::read(path).map_err(|e| what(&e))?;
    let file = object::File::parse(&*bytes).map_err(|e| what(&e))?;
    let mut s = Size::default();
    let (alloc, write, exec) = (
        object::elf::SHF_ALLOC.0,
        object::elf::SHF_WRITE.0,
        object::elf::SHF_EXECINSTR.0,
    );
    for section in file.sections() {
        let SectionFlags::Elf { sh_type, sh_flags } = section.flags() else {
            return Err(what(&"not an ELF section"));
        };
        let sh_flags = sh_flags.0;
        if sh_flags & alloc == 0 {
            continue;
        }
        let n = section.size();
        if sh_type == object::elf::SHT_NOBITS {
            s.bss += n;
        } else if sh_flags & write != 0 {
            s.data += n;
        } else if sh_flags & exec != 0 {
            s.text += n;
        } else {
            s.rodata += n;
        }
    }
    s.flash = s.text + s.rodata + s.data;
    s.ram = s.data + s.bss;
    let mut seen = HashSet::new();
    let mut symbols: Vec<Symbol> = file
        .symbols()
        .filter(|sym| {
            sym.is_definition()
                && sym.size() > 0
                && matches!(sym.kind(), SymbolKind::Text | SymbolKind::Data)
                // Aliases: one entry per (address, size); Thumb code addresses have bit 0 set.
                && seen.insert((sym.address() & !1, sym.size()))
        })
        .filter_map(|sym| {
            Some(Symbol {
                bytes: sym.size(),
                name: format!("{:#}", rustc_demangle::demangle(sym.name().ok()?)),
            })
        })
        .collect();
    symbols.sort_by(|a, b| b.bytes.cmp(&a.bytes).then_with(|| a.name.cmp(&b.name)));
    symbols.truncate(largest);
    // The EABI names are C symbols; compiler-builtins' GCC-named routines are mangled Rust
    // (`compiler_builtins::float::add::__adddf3`): the demangled name's last segment.
    let mut soft: Vec<String> = file
        .symbols()
        .filter(|sym| sym.is_definition())
        .filter_map(|sym| {
            let name = format!("{:#}", rustc_demangle::demangle(sym.name().ok()?));
            let routine = name.rsplit("::").next().unwrap_or(&name);
            is_soft_f64(routine).then(|| routine.to_string())
        })
        .collect();
    soft.sort();
    soft.dedup();
    Ok((s, symbols, soft))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn soft_f64_names() {
        for n in [
            "__aeabi_dadd",
            "__aeabi_dcmpeq",
            "__aeabi_d2f",
            "__aeabi_d2iz",
            "__aeabi_f2d",
            "__aeabi_i2d",
            "__aeabi_ul2d",
            "__adddf3",
            "__muldf3",
            "__eqdf2",
            "__unorddf2",
            "__extendsfdf2",
            "__truncdfsf2",
            "__fixdfsi",
            "__floatunsidf",
            "__powidf2",
        ] {
            assert!(is_soft_f64(n), "{n}");
        }
        for n in [
            "__aeabi_fadd",
            "__aeabi_uidiv",
            "__aeabi_idiv0",
            "__aeabi_memcpy",
            "__addsf3",
            "__sbss",
            "__defmt_default_timestamp",
            "_ZN4libm4math5tanhf5tanhf17h0123456789abcdefE",
            "main",
        ] {
            assert!(!is_soft_f64(n), "{n}");
        }
    }

    #[test]
    fn an_elf_image() {
        // This test's own executable (an ELF on the Linux hosts xtask runs on).
        let exe = std::env::current_exe().unwrap();
        let (s, largest, _) = read_elf(&exe, 5).unwrap();
        assert!(
            s.text > 0 && s.rodata > 0 && s.data > 0 && s.bss > 0,
            "{s:?}"
        );
        assert_eq!(s.flash, s.text + s.rodata + s.data);
        assert_eq!(s.ram, s.data + s.bss);
        assert_eq!(largest.len(), 5);
        assert!(largest.windows(2).all(|w| w[0].bytes >= w[1].bytes));
        assert!(largest[0].bytes > 0 && !largest[0].name.is_empty());
        let (_, none, _) = read_elf(&exe, 0).unwrap();
        assert!(none.is_empty());
        assert!(read_elf(Path::new("/nonexistent"), 1).is_err());
        assert!(read_elf(&crate::util::root().join("Cargo.toml"), 1).is_err());
    }
}
