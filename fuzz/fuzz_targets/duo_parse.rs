//! `.duo` decoding on arbitrary bytes: `DuoFile::parse` and, when it
//! accepts, binding a `Model` and reading every tensor must never panic.
#![no_main]

use duolando_core::format::DuoFile;
use duolando_core::model::Model;
use libfuzzer_sys::fuzz_target;

#[repr(C, align(64))]
struct Aligned([u8; 1 << 16]);

fuzz_target!(|data: &[u8]| {
    // The decoder requires a 64-byte aligned buffer: copy into one.
    let mut buf = Box::new(Aligned([0; 1 << 16]));
    let n = data.len().min(buf.0.len());
    buf.0[..n].copy_from_slice(&data[..n]);
    if let Ok(file) = DuoFile::parse(&buf.0[..n]) {
        for entry in file.tensors() {
            let t = file.tensor(entry.name).expect("a listed tensor must be readable");
            assert_eq!(t.dtype, entry.dtype);
        }
        let _ = Model::from_duo(&file);
    }
});
