//! `.duo` decoding on arbitrary bytes: `DuoFile::parse` and, when it
//! accepts, binding every family's `Model` and reading every tensor
//! must never panic.
#![no_main]

use duolando_core::format::DuoFile;
use duolando_core::bailando::model::Model as BailandoModel;
use duolando_core::duolando::model::Model;
use duolando_core::transflower::model::Model as TransflowerModel;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The decoder requires a 64-byte aligned buffer: copy into one.
    let mut storage = vec![0u8; data.len() + 64];
    let off = storage.as_ptr().align_offset(64);
    let buf = &mut storage[off..off + data.len()];
    buf.copy_from_slice(data);
    if let Ok(file) = DuoFile::parse(buf) {
        for entry in file.tensors() {
            let t = file.tensor(entry.name).expect("a listed tensor must be readable");
            assert_eq!(t.dtype, entry.dtype);
        }
        let _ = Model::from_duo(&file);
        let _ = BailandoModel::from_duo(&file);
        let _ = TransflowerModel::from_duo(&file);
    }
});
